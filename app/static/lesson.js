// Lessons on the page (app.ui.lessons): trame.utils.lmapdLesson.
// A lesson opened (the lesson state changed to a card) starts clean: every outline of an earlier
// lesson goes, the array image shows the whole array (zoomed to the lesson's pixels where the
// card is about the array image), the 3D views go back to their home cameras and the chart's
// cursor is cleared (the server sets the
// controls, colour mode, selection, and unpins a pinned frame: app.logic.lessons). On a phone or
// a narrow window the drawer closes; on a short screen (under 1000 px) the card folds to one
// line (its title, the view it is about and a button to unfold it); the card stays at the top
// of the window while the page scrolls, and the view it names is brought into sight just below
// it, outlined for a few seconds (again when the lesson's frame arrives, and when the card is
// unfolded: it grows over the view). A first visit shows a welcome line (link.js decides), until
// it is closed or a lesson is opened (``welcomed``: never again in this browser).
window.trame.utils.lmapdLesson = {
  pending: null,
  timer: null,
  opened(lesson) {
    const state = window.trame.state;
    this.clearOutlines();
    if (!lesson) { this.pending = null; return; }
    this.welcomed();
    if (window.innerWidth < 960) state.set('main_drawer', false);
    state.set('wave_cursor', '');
    ['scene_view', 'cloud_view'].forEach((ref) => {  // the 3D views' cameras: their own home
      const view = window.trame.refs && window.trame.refs[ref];
      if (view && view.resetCamera) view.resetCamera();
    });
    if (lesson.zoom === 'pixels') this.zoomTo(state.get('selected_pixels'));
    else state.set('array_zoom', { s: 1, x: 0, y: 0 });
    state.set('lesson_folded', window.innerHeight < 1000);
    this.bring(lesson.view_selector, 350);  // after the drawer's and the card's transitions
  },
  folded(isFolded) {  // the card unfolded: it grows, its view goes below it again
    const lesson = window.trame.state.get('lesson');
    if (!isFolded && lesson) this.bring(lesson.view_selector, 250);
  },
  bring(selector, delayMs) {
    this.pending = { selector, until: performance.now() + 30000 };
    setTimeout(() => this.show(), delayMs);
    if (!this.watching) this.watch();
  },
  // while a view is being brought into sight, the page may still grow above it (the panels
  // built after the first frame, an image, a chart's library): it is brought again at each
  // change of the page's height, until the user scrolls, taps or types
  watch() {
    this.watching = true;
    const main = document.querySelector('.v-main') || document.body;
    new ResizeObserver(() => {
      if (this.pending && performance.now() < this.pending.until) this.show(true);
    }).observe(main);
    const stop = () => { this.pending = null; };
    ['wheel', 'touchstart', 'keydown', 'mousedown'].forEach(
      (name) => window.addEventListener(name, stop, { passive: true, capture: true }));
  },
  clearOutlines() {
    clearTimeout(this.timer);
    document.querySelectorAll('.lesson-view').forEach((el) => el.classList.remove('lesson-view'));
  },
  zoomTo(pixels) {  // the array image zoomed (at most 4x) about the lesson's pixels
    const n = (window.trame.state.get('array_image') || {}).pixels;
    if (!n || !pixels || !pixels.length) return;
    const rows = pixels.map((p) => p[0]), cols = pixels.map((p) => p[1]);
    const extent = Math.max(Math.max(...rows) - Math.min(...rows),
      Math.max(...cols) - Math.min(...cols)) + n / 8;
    const s = Math.min(4, Math.max(1, n / extent)), m = 1 - 1 / s;
    const u = (Math.max(...cols) + Math.min(...cols) + 1) / 2 / n;
    const v = (Math.max(...rows) + Math.min(...rows) + 1) / 2 / n;
    const clamp = (a) => Math.min(m, Math.max(0, a));
    window.trame.state.set('array_zoom', { s, x: clamp(u - 0.5 / s), y: clamp(v - 0.5 / s) });
  },
  frame() {
    if (this.pending && performance.now() < this.pending.until) setTimeout(() => this.show(), 50);
  },
  show(again) {
    if (!this.pending) return;
    const view = document.querySelector(this.pending.selector);
    const card = document.querySelector('.lesson-card');
    if (!view) return;
    const bar = document.querySelector('.v-app-bar');
    const above = (bar ? bar.getBoundingClientRect().bottom : 0)
      + (card ? card.getBoundingClientRect().height : 0) + 8;
    const top = view.getBoundingClientRect().top + window.scrollY - above;
    window.scrollTo({ top: Math.max(0, top), behavior: 'instant' });
    if (again && view.classList.contains('lesson-view')) return;  // its outline still on
    this.clearOutlines();
    view.classList.add('lesson-view');
    this.timer = setTimeout(() => view.classList.remove('lesson-view'), 4000);
  },
  welcomed() {
    try { window.localStorage.setItem('lmapd-welcomed', '1'); } catch (e) { /* private mode */ }
    if (!window.trame.state.get('welcome_closed')) window.trame.state.set('welcome_closed', true);
  },
};
