// Binary payloads (app.payloads.encode): msgpack hands the page each ``bytes`` value as a
// Uint8Array; ``bin(value)`` returns the value with every ``{bytes, dtype, shape}`` replaced by the
// typed array vtk.js takes (copied into its own, aligned buffer), the same object for the same
// state value (so a view updates only when its value changes); ``imageUrl(image)`` an object URL
// of a ``{png}`` image (the previous one is released). The views' templates call it
// (app.ui.views3d, app.ui.panels).
window.trame.utils.lmapdBin = (() => {
  const TYPES = { uint8: Uint8Array, uint16: Uint16Array, uint32: Uint32Array,
                  int32: Int32Array, float32: Float32Array, float64: Float64Array };
  const made = new WeakMap();
  const typed = (v) => {
    const T = TYPES[v.dtype], own = new Uint8Array(v.bytes);  // a copy: aligned
    return new T(own.buffer, 0, own.byteLength / T.BYTES_PER_ELEMENT);
  };
  const bin = (v) => {
    if (!v || typeof v !== 'object' || ArrayBuffer.isView(v)) return v;
    if (made.has(v)) return made.get(v);
    let out;
    if (v.dtype && ArrayBuffer.isView(v.bytes)) out = typed(v);
    else if (Array.isArray(v)) out = v.map(bin);
    else out = Object.fromEntries(Object.entries(v).map(([k, x]) => [k, bin(x)]));
    made.set(v, out);
    return out;
  };
  let image = { of: null, url: '' };
  const imageUrl = (v) => {
    if (!v || !ArrayBuffer.isView(v.png)) return '';
    if (image.of !== v) {
      if (image.url) URL.revokeObjectURL(image.url);
      image = { of: v, url: URL.createObjectURL(new Blob([v.png], { type: 'image/png' })) };
    }
    return image.url;
  };
  return { bin, imageUrl };
})();
