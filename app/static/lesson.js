// An opened lesson brings its view into sight (app.ui.lessons): trame.utils.lmapdLesson.
// A lesson opened (the lesson state changed to a card): on a phone or a narrow window the
// drawer closes; on a short screen (under 1000 px) the card folds to one line (its title, the
// view it is about and a button to unfold it); the card stays at the top of the window while the
// page scrolls, and the view it names is brought into sight just below it, outlined for a few
// seconds (again when the lesson's frame arrives: a chart may grow meanwhile).
window.trame.utils.lmapdLesson = {
  pending: null,
  opened(lesson) {
    const state = window.trame.state;
    if (!lesson) { this.pending = null; return; }
    if (window.innerWidth < 960) state.set('main_drawer', false);
    if (lesson.view_selector === '.array-card') this.zoomTo(state.get('selected_pixels'));
    state.set('lesson_folded', window.innerHeight < 1000);
    this.pending = { selector: lesson.view_selector, until: performance.now() + 30000 };
    setTimeout(() => this.show(), 350);  // after the drawer's and the card's transitions
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
  show() {
    if (!this.pending) return;
    const view = document.querySelector(this.pending.selector);
    const card = document.querySelector('.lesson-card');
    if (!view) return;
    const bar = document.querySelector('.v-app-bar');
    const above = (bar ? bar.getBoundingClientRect().bottom : 0)
      + (card ? card.getBoundingClientRect().height : 0) + 8;
    const top = view.getBoundingClientRect().top + window.scrollY - above;
    window.scrollTo({ top: Math.max(0, top), behavior: 'instant' });
    view.classList.add('lesson-view');
    clearTimeout(this.timer);
    this.timer = setTimeout(() => view.classList.remove('lesson-view'), 4000);
  },
};
