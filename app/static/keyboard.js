// The page's keyboard helpers (app.ui.panels, app.ui.widgets): the log sliders' Page keys (a
// tenth of a decade), the array image's cursor pixel (arrow keys move it, Enter selects it,
// Shift+Enter adds it), and "Copy link"'s answer (trame.utils.lmapdCopy, app.ui.controls).
// Log sliders (a control box with data-a11y-log="1" and data-state-key): an arrow key moves the
// value by a hundredth of a decade (x 1.023: 500 -> 512 m), a Page key by a tenth (x 1.26), from
// the value itself (the thumb's position is rounded to its fine step), rounded to 3 digits like a
// drag's and kept within the slider's range; Vuetify's own steps (a thousandth of a decade per
// arrow: 500 -> 501 m) never run.
// The array image: lmapdArray.key(event, zoom, cursor, pixels, selected) returns the new
// [zoom, cursor]: arrows move the cursor one pixel (8 with Shift), the zoomed view following it;
// Ctrl + arrows pan; Enter (or Space) selects the cursor's pixel, Shift+Enter adds it (or takes
// it off); + and - zoom about the centre, 0 resets. The cursor's pixel goes to the readout.
(() => {
  const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
  const logSteps = { ArrowRight: 0.01, ArrowUp: 0.01, ArrowLeft: -0.01, ArrowDown: -0.01,
    PageUp: 0.1, PageDown: -0.1 };
  document.addEventListener('keydown', (e) => {
    const step = logSteps[e.key];
    if (step === undefined || e.altKey || e.ctrlKey || e.metaKey) return;
    const thumb = e.target && e.target.closest && e.target.closest('[role=slider]');
    const box = thumb && thumb.closest('[data-a11y-log="1"][data-state-key]');
    if (!box) return;
    e.preventDefault();
    e.stopPropagation();  // Vuetify's own step never runs
    const key = box.dataset.stateKey, value = Number(window.trame.state.get(key));
    const lo = 10 ** Number(thumb.getAttribute('aria-valuemin'));
    const hi = 10 ** Number(thumb.getAttribute('aria-valuemax'));
    if (!(value > 0)) return;
    const next = clamp(Number((10 ** (Math.log10(value) + step)).toPrecision(3)), lo, hi);
    window.trame.state.set(key, Number(next.toPrecision(6)));
  }, true);
  const zoomBy = (z, f, u, v) => {
    const s = clamp(z.s * f, 1, 16), m = 1 - 1 / s;
    return { s, x: clamp(z.x + u / z.s - u / s, 0, m), y: clamp(z.y + v / z.s - v / s, 0, m) };
  };
  const follow = (z, c, n) => {  // the zoomed window moved to hold the cursor's pixel
    const m = 1 - 1 / z.s, u = (c[1] + 0.5) / n, v = (c[0] + 0.5) / n, w = 1 / z.s;
    const x = (u < z.x || u > z.x + w) ? clamp(u - w / 2, 0, m) : z.x;
    const y = (v < z.y || v > z.y + w) ? clamp(v - w / 2, 0, m) : z.y;
    return { s: z.s, x, y };
  };
  // "Copy link": the clipboard's answer as the message the page confirms with
  window.trame.utils.lmapdCopy = (text) => (navigator.clipboard
    ? navigator.clipboard.writeText(text).then(
      () => `Link copied (${text.length} characters)`,
      () => 'Could not copy: select the link above and press Ctrl+C')
    : Promise.resolve('Select the link above and press Ctrl+C to copy it'));
  window.trame.utils.lmapdArray = {
    key(e, z, cursor, n, selected) {
      const moves = { ArrowLeft: [0, -1], ArrowRight: [0, 1], ArrowUp: [-1, 0], ArrowDown: [1, 0] };
      const half = Math.floor((n || 1) / 2);
      let c = cursor && cursor[0] < n && cursor[1] < n ? cursor
        : (selected && selected.length ? selected[selected.length - 1] : [half, half]);
      const move = moves[e.key];
      if (move && e.ctrlKey) {  // pan
        e.preventDefault();
        const d = 0.2 / z.s, m = 1 - 1 / z.s;
        return [{ s: z.s, x: clamp(z.x + move[1] * d, 0, m), y: clamp(z.y + move[0] * d, 0, m) },
          cursor];
      }
      if (move) {
        e.preventDefault();
        const step = e.shiftKey ? 8 : 1;
        c = [clamp(c[0] + move[0] * step, 0, n - 1), clamp(c[1] + move[1] * step, 0, n - 1)];
        window.trame.trigger('pixel_hover', c);
        return [follow(z, c, n), c];
      }
      if (e.key === 'Enter' || e.key === ' ') {
        e.preventDefault();
        window.trame.trigger('pixel_click', [c[0], c[1], e.shiftKey]);
        return [z, c];
      }
      if (e.key === '+' || e.key === '=') return [zoomBy(z, 1.5, 0.5, 0.5), cursor];
      if (e.key === '-' || e.key === '_') return [zoomBy(z, 1 / 1.5, 0.5, 0.5), cursor];
      if (e.key === '0') return [{ s: 1, x: 0, y: 0 }, cursor];
      return [z, cursor];
    },
  };
})();
