// Frame pacing (app.logic.pacing): after the page applied a frame, wait until it is on screen, then
// tell the server (the trigger frame_shown) and keep a log of those times for the benchmark
// (window.lmapdFrames). On screen: a WebGL canvas reaches the screen in the compositor's commit
// after vtk.js rendered it (with software WebGL the commit waits for the rendering and reads the
// canvas back), so the time is taken two animation frames after the views' last render, once
// each view has rendered at its canvas's present size. The page's first frame is applied while
// the page mounts, before its views exist; vtk.js first renders a new view empty at 300 x 300
// pixels, then at its own size with the frame's data (about 0.4 s later in software).
// Renders are seen at the views' WebGL contexts (vtk.js freezes its own objects): every render
// clears the canvas first. Frames are logged and reported in the order they were applied. Once
// the first is on screen the drawer's controls are built (trame.utils.lmapd.page.controls).
// Vue templates cannot reach browser globals, so the helper hangs on trame.utils
// (app.ui.layout.FRAME_SHOWN calls it when the state's frame_key changes).
(() => {
  // every WebGL canvas's last clear, { t, size }, from the canvas's first context on (this file
  // is loaded before the page mounts its views)
  const clears = new WeakMap();
  const VIEWS = ['scene_view', 'cloud_view'];
  const MAX_RENDERS = 8, MAX_WAITS = 60;  // pairs of animation frames: bounds only
  // The drawer's controls are built once the first frame is on screen (app.ui.controls), or
  // at the latest this long after the page loads (a page whose frame does not come) [s]. The
  // flag is the page's own, never the server's state: once set it stays (a state the server
  // sends again, as after a reconnection, cannot take the controls away).
  const CONTROLS_LATEST_S = 4;
  const page = window.Vue.reactive({ controls: false });
  const controlsReady = () => { page.controls = true; };
  setTimeout(controlsReady, CONTROLS_LATEST_S * 1000);
  const sizeOf = (canvas) => `${canvas.width}x${canvas.height}`;
  const getContext = HTMLCanvasElement.prototype.getContext;
  // WebGL drawn in software (a browser without a usable GPU: SwiftShader, Mesa's llvmpipe)
  // draws the views without multisampling: there antialiasing is the views' costliest option
  // (a new tab's first picture about 0.2-0.3 s later on this project's 2-core machine:
  // docs/serving.md), while a GPU does it for next to nothing, so it stays on there. Which one
  // this browser has is read once, from a context of its own, before the views' first context;
  // a browser that does not say (no WEBGL_debug_renderer_info) keeps the default.
  const SOFTWARE_GL = /swiftshader|llvmpipe|softpipe|software|basic render/i;
  let software = null;
  const softwareGL = () => {
    if (software === null) {
      const probe = getContext.call(document.createElement('canvas'), 'webgl');
      const info = probe && probe.getExtension('WEBGL_debug_renderer_info');
      const renderer = info ? String(probe.getParameter(info.UNMASKED_RENDERER_WEBGL)) : '';
      software = SOFTWARE_GL.test(renderer);
      const lose = probe && probe.getExtension('WEBGL_lose_context');
      if (lose) lose.loseContext();
    }
    return software;
  };
  HTMLCanvasElement.prototype.getContext = function (type, options, ...rest) {
    const webgl = String(type).startsWith('webgl');
    if (webgl && softwareGL()) options = { ...(options || {}), antialias: false };
    const gl = getContext.call(this, type, options, ...rest);
    if (gl && webgl && !clears.has(this)) {
      const canvas = this, clear = gl.clear;
      clears.set(canvas, { t: 0, size: '' });
      gl.clear = (...args) => {
        clears.set(canvas, { t: performance.now(), size: sizeOf(canvas) });
        return clear.apply(gl, args);
      };
    }
    return gl;
  };

  window.trame.utils.lmapd = {
    page,  // { controls }: read by the drawer's template (app.ui.controls.CONTROLS_READY)
    softwareGL,  // whether this browser draws WebGL in software (its views then unsmoothed)
    pending: [],  // frames applied and not yet reported: { key, applied }
    // the views' last clears ([] until every view has a context)
    viewClears() {
      const found = [];
      for (const ref of VIEWS) {
        const view = window.trame.refs[ref];
        const api = view && view.$ && view.$.provides && view.$.provides.view;
        const canvas = api && api.openglRenderWindow && api.openglRenderWindow.getCanvas();
        if (!canvas || !clears.has(canvas)) return [];
        found.push({ ...clears.get(canvas), now: sizeOf(canvas) });
      }
      return found;
    },
    frameShown(key) {
      if (!key) return;
      const applied = performance.now();
      this.pending.push({ key, applied });
      let mark = applied;
      const onScreen = (renders, waits) => requestAnimationFrame(() => requestAnimationFrame(() => {
        if (!this.pending.some((f) => f.key === key)) return;  // reported with a newer frame
        const views = this.viewClears();
        const unsized = !views.length || views.some((v) => v.size !== v.now);
        if (unsized && waits > 0) {  // a view not rendered at its size yet
          onScreen(renders, waits - 1);
          return;
        }
        const last = Math.max(0, ...views.map((v) => v.t));
        if (last > mark && renders > 0) {  // a view rendered meanwhile: its commit next
          mark = performance.now();
          onScreen(renders - 1, waits);
          return;
        }
        this.report(key);
      }));
      setTimeout(() => onScreen(MAX_RENDERS, MAX_WAITS), 0);
    },
    // The view ``ref``'s camera reset goes to ``camera`` (the state's home camera: the view's
    // reset_camera event, app.ui.views3d). A new vtk.js view resets its camera as it mounts and
    // again 100 ms later (trame-vtk's VtkView, for data that come after the mount); that second
    // reset would only set the same home camera again and draw both views once more (with WebGL
    // in software, about 0.15 s of a first picture), so it is called off here: the view's data
    // come with the state, and each later frame's camera is set by the server.
    setCamera(ref, camera) {
      const view = window.trame.refs[ref];
      if (!view) return;
      view.setCamera(camera);
      const api = view.$ && view.$.provides && view.$.provides.view;
      // the mount's reset calls this before it sets its timer: called off once the mount is done
      queueMicrotask(() => {
        if (api && api.resetCameraTimeout) {
          clearTimeout(api.resetCameraTimeout);
          api.resetCameraTimeout = null;
        }
      });
    },
    // report frame ``key`` shown, and the frames applied before it that are still waiting
    report(key) {
      const upto = this.pending.findIndex((f) => f.key === key);
      const t = performance.now();
      for (const { key: k, applied } of this.pending.splice(0, upto + 1)) {
        const kind = k[0] === 'p' ? 'preview' : 'preset';
        (window.lmapdFrames = window.lmapdFrames || []).push({ key: k, kind, applied, t });
        window.trame.trigger('frame_shown', [k]);
      }
      setTimeout(controlsReady, 0);  // after this frame's commit
    },
  };
})();
