// Accessible names and spoken values where the widgets cannot set them: Vuetify puts a slider's
// aria-label on its wrapper, not on the thumb (role "slider") a screen reader reads, and a text
// field's input points to a label that does not exist, a select's box has no name; plotly's tool
// buttons are unnamed links.
// A control's box carries data-a11y-name / -unit / -log (app.ui.widgets.a11y_attributes): this
// names its thumb and input and keeps the thumb's aria-valuetext the value with its unit
// ("500 m", not the log10 position 2.699). Re-applied, at most once per animation frame,
// whenever the page changes.
(() => {
  const spoken = (box, thumb) => {
    let v = Number(thumb.getAttribute('aria-valuenow'));
    if (box.dataset.a11yLog === '1') v = Number((10 ** v).toPrecision(3));
    const key = box.dataset.stateKey, held = key ? Number(window.trame.state.get(key)) : NaN;
    if (Number.isFinite(held)) v = held;  // the value itself, not the thumb's rounded place
    const unit = box.dataset.a11yUnit;
    return `${Number(v.toPrecision(6))}${unit ? ' ' + unit : ''}`;
  };
  const set = (el, name, value) => {
    if (el.getAttribute(name) !== value) el.setAttribute(name, value);
  };
  const label = () => {
    document.querySelectorAll('[data-a11y-name]').forEach((box) => {
      const name = box.dataset.a11yName, unit = box.dataset.a11yUnit;
      box.querySelectorAll('[role=slider]').forEach((thumb) => {
        set(thumb, 'aria-label', name);
        set(thumb, 'aria-valuetext', spoken(box, thumb));
      });
      box.querySelectorAll('input').forEach((input) => {
        const by = input.getAttribute('aria-labelledby');
        if (by && !document.getElementById(by)) input.removeAttribute('aria-labelledby');
        set(input, 'aria-label', `${name}${unit ? ' in ' + unit : ''}`);
      });
    });
    document.querySelectorAll('.v-field[role=combobox]').forEach((field) => {
      const text = (field.querySelector('label') || {}).textContent;
      if (text && text.trim()) set(field, 'aria-label', text.trim());
    });
    document.querySelectorAll('a.modebar-btn').forEach((a) => {
      set(a, 'aria-label', a.dataset.title || 'chart tool');
    });
  };
  let pending = false;
  new MutationObserver(() => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; label(); });
  }).observe(document.body, {
    subtree: true, childList: true, attributes: true, attributeFilter: ['aria-valuenow'],
  });
  label();
})();
