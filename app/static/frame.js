// Frame pacing (app.logic.pacing): after the page applied a frame, wait until it is on screen, then
// tell the server (the trigger frame_shown) and keep a log of those times for the benchmark
// (window.lmapdFrames). On screen: a WebGL canvas reaches the screen in the compositor's commit
// after vtk.js rendered it (with software WebGL the commit waits for the rendering and reads the
// canvas back), so the time is taken two animation frames after the views' last render (each
// render is stamped), not two after the state arrived.
// Vue templates cannot reach browser globals, so the helper hangs on trame.utils
// (app.ui.layout.FRAME_SHOWN calls it when the state's frame_key changes).
window.trame.utils.lmapd = {
  lastRender: 0,
  watchViews() {
    for (const ref of ['scene_view', 'cloud_view']) {
      const view = window.trame.refs[ref];
      const rw = view && view.$ && view.$.provides && view.$.provides.view
        && view.$.provides.view.renderWindow;
      if (!rw || rw.lmapdStamped) continue;
      const render = rw.render;
      rw.render = (...args) => { this.lastRender = performance.now(); return render(...args); };
      rw.lmapdStamped = true;
    }
  },
  frameShown(key) {
    if (!key) return;
    const applied = performance.now();
    this.watchViews();
    let mark = applied;
    const onScreen = (tries) => requestAnimationFrame(() => requestAnimationFrame(() => {
      if (this.lastRender > mark && tries > 0) {  // a view rendered meanwhile: its commit next
        mark = performance.now();
        onScreen(tries - 1);
        return;
      }
      const kind = key[0] === 'p' ? 'preview' : 'preset', t = performance.now();
      (window.lmapdFrames = window.lmapdFrames || []).push({ key, kind, applied, t });
      window.trame.trigger('frame_shown', [key]);
    }));
    setTimeout(() => onScreen(8), 0);
  },
};
