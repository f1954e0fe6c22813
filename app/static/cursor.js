// The waveform chart's measuring cursor (app.ui.panels): a click on a trace sets cursor A at that
// time, the next click cursor B, the one after starts again with A. Each cursor is a dashed line
// on the chart, and the readout under it gives its time and range (c t / 2) and, with both, the
// difference: the time between two peaks, and the depth between the surfaces that returned them.
// The cursors are this page's own (no server call) and stay while the chart is redrawn for
// another frame or pixel (they are drawn again after each plot).
window.trame.utils.lmapdCursor = (() => {
  const C_M_S = 299792458;
  const COLORS = ['#00897b', '#6a1b9a'];
  let marks = [];  // cursor times [ns]: A, then B
  const chart = () => document.querySelector('.waveform-box .js-plotly-plot');
  const ns = (t) => `${t.toLocaleString('en-US', { minimumFractionDigits: 2, maximumFractionDigits: 2 })} ns`;
  const metres = (t) => `${(t * 1e-9 * C_M_S / 2).toLocaleString('en-US', { minimumFractionDigits: 3, maximumFractionDigits: 3 })} m`;
  const shapes = () => marks.map((x, i) => ({
    type: 'line', name: 'cursor', xref: 'x', yref: 'paper', x0: x, x1: x, y0: 0, y1: 1,
    line: { color: COLORS[i], width: 1.5, dash: 'dash' },
  }));
  const drawn = (gd) => (gd.layout.shapes || []).filter((s) => s.name === 'cursor').length;
  const draw = () => {
    const gd = chart();
    if (!gd || !gd.layout || !window.Plotly) return;
    const kept = (gd.layout.shapes || []).filter((s) => s.name !== 'cursor');
    window.Plotly.relayout(gd, { shapes: kept.concat(shapes()) });
  };
  const text = () => {
    if (!marks.length) return '';
    const [a, b] = marks;
    let out = `A: ${ns(a)} (${metres(a)})`;
    if (b !== undefined) {
      const d = Math.abs(b - a);
      out += `, B: ${ns(b)} (${metres(b)}); B − A: ${ns(d)}, ${metres(d)} in range`;
    }
    return out;
  };
  return {
    // the readout after a click on the chart (plotly's click event: the points under it)
    click(event) {
      const point = event && event.points && event.points[0];
      if (!point || typeof point.x !== 'number' || !Number.isFinite(point.x)) return text();
      marks = marks.length === 1 ? [marks[0], point.x] : [point.x];
      draw();
      return text();
    },
    clear() {
      marks = [];
      draw();
      return '';
    },
    // after each plot: the cursors again, if the new layout dropped them
    redraw() {
      const gd = chart();
      if (gd && gd.layout && drawn(gd) !== marks.length) draw();
    },
    marks: () => marks.slice(),
    text,
  };
})();
