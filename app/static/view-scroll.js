// The 3D views do not capture the page's scroll: the mouse wheel over a view scrolls the page
// unless Ctrl (or Cmd, or a trackpad pinch) is held or the view was clicked (until the pointer
// leaves it); a wheel event meant for the page never reaches vtk.js's interactor. A view clicked
// or tapped is "active" (a thin blue frame), and only then does a finger swipe over it rotate it
// (page.css: touch-action).
(() => {
  const viewOf = (e) => (e.target && e.target.closest ? e.target.closest('.vtk-box') : null);
  document.addEventListener('pointerdown', (e) => {
    const box = viewOf(e);
    document.querySelectorAll('.vtk-box.view-active').forEach((b) => {
      if (b !== box) b.classList.remove('view-active');
    });
    if (box) box.classList.add('view-active');
  }, true);
  document.addEventListener('pointerout', (e) => {
    const box = viewOf(e);
    if (box && e.pointerType === 'mouse' && !box.contains(e.relatedTarget)) {
      box.classList.remove('view-active');
    }
  }, true);
  document.addEventListener('wheel', (e) => {
    const box = viewOf(e);
    if (box && !e.ctrlKey && !e.metaKey && !box.classList.contains('view-active')) {
      e.stopPropagation();  // vtk.js never sees it: the page scrolls
    }
  }, { capture: true, passive: true });
})();
