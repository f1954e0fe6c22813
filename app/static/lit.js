// The 3D scene's lit side (app.payloads.scene3d.lit_side): ``colors(lit)`` the RGB of each facet
// (three bytes a facet, the lit-side actor's cell scalars) from its two bits, the Sun's and the
// Earth's (packed eight facets to a byte, the first in the high bit), through the payload's
// palette (neither, Sun, Earth, both); the same array for the same state value, an empty one for
// none (the data array's values are never null).
// ``shown(show, lit, polys)``: the switch is on and the lit side is the mesh's whose triangle
// cells ``polys`` the page holds (a new target's mesh comes before its first frame's lit side).
window.trame.utils.lmapdLit = (() => {
  const made = new WeakMap(), NONE = new Uint8Array(0);
  const bits = (v) => {
    const typed = window.trame.utils.lmapdBin.bin(v);
    return ArrayBuffer.isView(typed) ? typed : new Uint8Array(0);
  };
  const colors = (lit) => {
    if (!lit || typeof lit !== 'object') return NONE;
    if (made.has(lit)) return made.get(lit);
    const sun = bits(lit.sun), earth = bits(lit.earth), n = lit.n_facets;
    const out = new Uint8Array(3 * n);
    for (let i = 0; i < n; i++) {
      const byte = i >> 3, shift = 7 - (i & 7);
      const k = ((sun[byte] >> shift) & 1) + 2 * ((earth[byte] >> shift) & 1);
      out.set(lit.palette[k], 3 * i);
    }
    made.set(lit, out);
    return out;
  };
  const shown = (show, lit, polys) => !!(show && lit && polys && polys.shape
    && polys.shape[0] === 4 * lit.n_facets);
  return { colors, shown };
})();
