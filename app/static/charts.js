// The charts' library after the first picture (app.ui.charts): plotly's script (trame-plotly's
// bundle, 4.6 MB: about 0.6 s of a page's CPU to evaluate on this project's machines, more than
// Vue, Vuetify and vtk.js together) is not among the scripts the page loads before it mounts. This
// Vue plugin (installed through trame's vue_use) registers the chart component, TramePlotly, as an
// async component whose loader waits until the page has shown its first frame (frame.js's
// window.lmapdFrames) and the server has no other on its way (at most 15 s after the mount), then
// loads the script and hands over trame-plotly's own component: each chart mounts then, with the
// state's figure at that time.
// window.lmapdCharts tells when the script was asked for, when it ran, and when the charts had
// mounted with it (a task after the component was handed over: tests/support's wait_settled).
window.trame.utils.lmapdCharts = (() => {
  const LATEST_S = 15;  // a page that shows no frame (the server's error) still gets its charts
  const times = (window.lmapdCharts = { requested: null, loaded: null, mounted: null });
  let component = null;
  // the first frame on screen and the server idle (no frame on its way, such as the chosen
  // preset's after a preview), looked at every 100 ms
  const firstFrame = () => new Promise((resolve) => {
    const until = performance.now() + LATEST_S * 1000;
    const check = () => {
      const shown = (window.lmapdFrames || []).length > 0 && !window.trame.state.get('busy');
      if (shown || performance.now() > until) resolve(); else setTimeout(check, 100);
    };
    check();
  });
  // after the frame's own work (its commit, the views' renders): an idle moment, or 0.5 s
  const idle = () => new Promise((resolve) => (
    window.requestIdleCallback ? requestIdleCallback(resolve, { timeout: 500 }) : setTimeout(resolve, 0)));
  const script = (src) => new Promise((resolve, reject) => {
    const tag = document.createElement('script');
    tag.src = src;
    tag.onload = resolve;
    tag.onerror = () => reject(new Error(`the charts' library did not load: ${src}`));
    document.body.appendChild(tag);
  });
  const load = async (scripts) => {
    await firstFrame();
    await idle();
    times.requested = performance.now();
    for (const src of scripts) await script(src);
    times.loaded = performance.now();
    const found = {};
    window.trame_plotly.install({ component: (name, def) => { found[name] = def; } });
    if (!found.TramePlotly) throw new Error("trame-plotly's bundle registered no TramePlotly");
    setTimeout(() => { times.mounted = performance.now(); }, 0);  // after Vue's render of them
    return found.TramePlotly;
  };
  return {
    install(app, options) {
      let pending = null;
      app.component('TramePlotly', window.Vue.defineAsyncComponent(() => {
        if (component) return Promise.resolve(component);
        pending = pending || load(options.scripts).then((c) => (component = c));
        return pending;
      }));
    },
    times,
  };
})();
