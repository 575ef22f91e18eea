// tracer's comparison viewer: the reference and every compared render on one canvas, drawn
// from their 32-bit float pixels (viewer_data.js, written by tracer/study/viewer.py).
//
// Keys: 1-9 an image (1 = reference), left/right arrows the previous/next one; i r f e v the
// view (image, relative error, FLIP, efficiency, variance); + and - exposure by half a stop,
// 0 back to the report's; s sRGB curve on/off; [ ] lower/raise the top of a map's range and
// { } its bottom; z fit the image. Wheel: zoom about the cursor (every image shares it); drag:
// pan; click: hold the readout on a pixel (click again to let it follow the cursor).
//
// Every number shown is computed here from the packed floats with the formulas of
// tracer/study/metrics.py, so the maps agree with the static PNGs of the same report.
(function () {
  "use strict";

  // The style and the sortable tables first: the page has its table whether or not it has the
  // viewer's data.
  const style = el("style", {}, `
.viewer { flex: 1 1 640px; min-width: 320px; }
.viewer-layout { display: flex; flex-wrap: wrap; gap: 1.5em; align-items: flex-start; }
.viewer-side { flex: 0 1 auto; }
.viewer-bar { display: flex; flex-wrap: wrap; gap: 0.3em; align-items: center; margin: 0.25em 0; }
.viewer-bar button { font: inherit; font-size: 0.85em; padding: 0.15em 0.5em; border: 1px solid #999;
  background: #eee; border-radius: 3px; cursor: pointer; }
.viewer-bar button.on { background: #345; color: #fff; border-color: #345; }
.viewer-bar label { font-size: 0.85em; margin-left: 0.6em; }
.viewer-bar input[type=number] { width: 4.5em; }
.viewer-stage { position: relative; display: inline-block; vertical-align: top; background: #1d1d1d;
  overflow: hidden; cursor: crosshair; user-select: none; }
.viewer-stage canvas { display: block; }
.viewer-caption { position: absolute; left: 6px; top: 4px; color: #fff; font-size: 0.85em;
  background: rgba(0, 0, 0, 0.55); padding: 1px 5px; border-radius: 3px; pointer-events: none; }
.viewer-why { position: absolute; inset: 0; display: flex; align-items: center; justify-content: center;
  color: #ddd; font-size: 0.95em; pointer-events: none; }
.viewer-scale { display: flex; align-items: center; gap: 0.5em; font-size: 0.8em; margin: 0.3em 0; }
.viewer-scale canvas { border: 1px solid #999; }
table.readout { font-size: 0.85em; margin: 0.4em 0; }
table.readout td { font-family: monospace; text-align: right; }
table.readout td:first-child { font-family: sans-serif; text-align: left; }
table.sortable th { cursor: pointer; }
table#metrics tr.current td { background: #dde6f0; }
table.sortable th[data-order=ascending]::after { content: " \\25B2"; }
table.sortable th[data-order=descending]::after { content: " \\25BC"; }
.viewer-keys { font-size: 0.8em; color: #555; max-width: 40em; }
`);
  document.head.append(style);
  document.querySelectorAll("table.sortable").forEach(sortable);

  const data = window.TRACER_VIEWER_DATA;
  const root = document.getElementById("tracer-viewer");
  if (!root || root.dataset.omitted) return;  // no viewer on the page, or left out (it says why)
  if (!data || data.format !== "tracer-viewer") {
    root.textContent = "The viewer's data (viewer_data.js) is missing or not a tracer viewer file.";
    return;
  }
  const W = data.width, H = data.height, N = W * H;
  const VIEWS = [
    {key: "i", id: "image", title: "image"},
    {key: "r", id: "relerr", title: "relative error"},
    {key: "f", id: "flip", title: "FLIP"},
    {key: "e", id: "efficiency", title: "efficiency"},
    {key: "v", id: "variance", title: "variance"},
  ];

  function decode(text) {
    // base64 -> Float32Array; the bytes are little-endian, as every browser's typed arrays are
    // on the little-endian machines browsers run on (checked below, once).
    const binary = atob(text), bytes = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);  // no call per byte
    return new Float32Array(bytes.buffer);
  }
  if (new Uint8Array(new Float32Array([1]).buffer)[3] !== 0x3f) {
    root.textContent = "This browser's floats are big-endian; the viewer cannot read its data.";
    return;
  }

  const images = data.images.map((entry) => ({
    name: entry.name, spp: entry.spp, seconds: entry.seconds, unit: entry.unit,
    // The reference's variance (and spp) are null where they are not known: another renderer's image.
    mean: decode(entry.mean), variance: entry.variance ? decode(entry.variance) : null,
    flip: entry.flip ? decode(entry.flip) : null,
  }));
  const reference = images[0];

  const state = {
    image: images.length > 1 ? 1 : 0, view: "image", exposure: data.exposure, srgb: true,
    baseline: data.baseline === null ? 0 : data.baseline,
    ranges: Object.fromEntries(Object.entries(data.views).map(([k, v]) => [k, v.range.slice()])),
    scale: 1, ox: 0, oy: 0, pinned: null, hover: null,
  };

  // ------------------------------------------------------------------------------------------
  // Per-pixel quantities (metrics.py): computed once per image and cached.

  const cache = new Map();
  function cached(key, make) {
    if (!cache.has(key)) cache.set(key, make());
    return cache.get(key);
  }

  function channelMean(i, term) {
    // Per pixel, the mean over channels of term(value, reference value) for image i.
    const a = images[i].mean, r = reference.mean, out = new Float64Array(N);
    for (let p = 0; p < N; p++) {
      let s = 0;
      for (let c = 0; c < 3; c++) s += term(a[3 * p + c], r[3 * p + c]);
      out[p] = s / 3;
    }
    return out;
  }

  function relerr(i) {
    // Mean over channels of (I - R)^2 / (R^2 + epsilon): metrics.relative_squared_error.
    return cached("relerr" + i,
      () => channelMean(i, (v, ref) => ((v - ref) * (v - ref)) / (ref * ref + data.relmse_epsilon)));
  }

  function boxBlur(values, radius) {
    // Mean over the (2 radius + 1)^2 window, clipped at the borders: metrics.box_blur.
    let cur = Float64Array.from(values);
    for (const axis of [0, 1]) {
      const out = new Float64Array(N);
      const n = axis === 0 ? H : W;
      for (let y = 0; y < H; y++) {
        for (let x = 0; x < W; x++) {
          const at = axis === 0 ? y : x;
          const lo = Math.max(0, at - radius), hi = Math.min(n - 1, at + radius);
          let s = 0;
          for (let k = lo; k <= hi; k++) s += axis === 0 ? cur[k * W + x] : cur[y * W + k];
          out[y * W + x] = s / (hi - lo + 1);
        }
      }
      cur = out;
    }
    return cur;
  }

  function squaredErrorCost(i) {
    // The channel-mean squared error against the reference, box-blurred, times seconds.
    return cached("cost" + i, () => {
      const err = channelMean(i, (v, ref) => (v - ref) * (v - ref));
      const blurred = boxBlur(err, data.efficiency_radius);
      for (let p = 0; p < N; p++) blurred[p] *= images[i].seconds;
      return blurred;
    });
  }

  function efficiency(i, j) {
    // log2 efficiency(i) / efficiency(j): metrics.efficiency_ratio_map; 0 where both are exact.
    return cached("eff" + i + "/" + j, () => {
      const a = squaredErrorCost(i), b = squaredErrorCost(j), tiny = 1e-30, out = new Float64Array(N);
      for (let p = 0; p < N; p++) {
        out[p] = a[p] <= tiny && b[p] <= tiny ? 0 : Math.log2((b[p] + tiny) / (a[p] + tiny));
      }
      return out;
    });
  }

  function logVariance(i) {
    return cached("var" + i, () => {
      const v = images[i].variance, out = new Float64Array(N);
      for (let p = 0; p < N; p++) out[p] = Math.log10((v[3 * p] + v[3 * p + 1] + v[3 * p + 2]) / 3);
      return out;
    });
  }

  // What the current view shows for image i: an (H W) map on its range, or null with a reason.
  function viewMap(i) {
    switch (state.view) {
      case "relerr":
        if (i === 0) return {why: "the reference has no error against itself"};
        return {values: cached("logrelerr" + i, () => relerr(i).map((v) => Math.log10(v + 1e-12)))};
      case "flip":
        if (!images[i].flip) return {why: "FLIP compares a render with the reference"};
        return {values: images[i].flip};
      case "efficiency":
        if (images.length < 3) return {why: "efficiency compares two renders: this report has one"};
        if (i === 0 || state.baseline === 0) return {why: "efficiency compares two renders (not the reference)"};
        if (i === state.baseline) return {why: "choose another image to compare against"};
        if (!(images[i].seconds > 0 && images[state.baseline].seconds > 0)) {
          return {why: "efficiency needs both renders' times, and one has none"};
        }
        return {values: efficiency(i, state.baseline)};
      case "variance":
        if (!images[i].variance) {
          return {why: "the reference's variance is not known (another renderer's image, without " +
                       "variance channels or a sample count)"};
        }
        return {values: logVariance(i)};
      default:
        return null;
    }
  }

  // ------------------------------------------------------------------------------------------
  // The page: toolbar, canvas, colour scale, readout.

  // The settings' inputs give the focus back after a change (blur), so that the keys, which
  // are ignored while an input has the focus, work again at once.
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "class") node.className = v;
      else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
      else node.setAttribute(k, v);
    }
    for (const child of children) node.append(child);
    return node;
  }


  const imageBar = el("div", {class: "viewer-bar", id: "viewer-images"});
  images.forEach((image, i) => {
    const label = i < 9 ? `${i + 1} ` : "";
    imageBar.append(el("button", {"data-index": i, onclick: () => setImage(i)}, label + image.name));
  });
  const viewBar = el("div", {class: "viewer-bar", id: "viewer-views"});
  for (const view of VIEWS) {
    viewBar.append(el("button", {"data-view": view.id, onclick: () => setView(view.id)},
      `${view.key} ${view.title}`));
  }
  const exposureBox = el("input", {type: "number", step: "0.5", id: "viewer-exposure",
    onchange: () => {
      const value = exposureBox.value === "" ? NaN : Number(exposureBox.value);
      if (Number.isFinite(value)) state.exposure = value;
      exposureBox.blur();
      redraw(true);
    }});
  const srgbBox = el("input", {type: "checkbox", id: "viewer-srgb",
    onchange: () => { state.srgb = srgbBox.checked; srgbBox.blur(); redraw(true); }});
  const rangeLow = el("input", {type: "number", step: "any", id: "viewer-range-low",
    onchange: () => { rangeLow.blur(); setRange(0, rangeLow.value); }});
  const rangeHigh = el("input", {type: "number", step: "any", id: "viewer-range-high",
    onchange: () => { rangeHigh.blur(); setRange(1, rangeHigh.value); }});
  const baselineBox = el("select", {id: "viewer-baseline",
    onchange: () => { state.baseline = Number(baselineBox.value); baselineBox.blur(); redraw(true); }});
  images.forEach((image, i) => { if (i > 0) baselineBox.append(el("option", {value: i}, image.name)); });
  const settingsBar = el("div", {class: "viewer-bar"},
    el("label", {}, "exposure (stops) ", exposureBox),
    el("label", {}, srgbBox, " sRGB"),
    el("label", {class: "range"}, "range ", rangeLow, " to ", rangeHigh),
    el("label", {class: "against"}, "efficiency against ", baselineBox),
    el("button", {onclick: fit}, "z fit"));

  const stage = el("div", {class: "viewer-stage"});
  const canvas = el("canvas", {id: "viewer-canvas"});
  const caption = el("div", {class: "viewer-caption", id: "viewer-caption"});
  const why = el("div", {class: "viewer-why", id: "viewer-why"});
  stage.append(canvas, caption, why);
  const scaleCanvas = el("canvas", {width: 256, height: 12});
  const scaleLow = el("span", {id: "viewer-scale-low"}), scaleHigh = el("span", {id: "viewer-scale-high"});
  const scaleLabel = el("span", {id: "viewer-scale-label"});
  const scale = el("div", {class: "viewer-scale", id: "viewer-scale"}, scaleLow, scaleCanvas, scaleHigh, scaleLabel);

  const FIELDS = [
    ["pixel", "pixel (x, y)"], ["image", "image"], ["value", "value (R G B)"],
    ["reference", "reference (R G B)"], ["error", "error I − R (R G B)"],
    ["relerr", "relative squared error"], ["variance", "variance of the mean (R G B)"],
    ["flip", "FLIP"], ["efficiency", "log2 efficiency ratio"],
  ];
  const readout = el("table", {class: "readout", id: "readout"});
  const cells = {};
  for (const [field, title] of FIELDS) {
    cells[field] = el("td", {"data-field": field});
    readout.append(el("tr", {}, el("td", {}, title), cells[field]));
  }
  const keys = el("p", {class: "viewer-keys"},
    "Keys: 1-9 an image (1 = reference), ← → flip; i r f e v the view (image, relative error, FLIP, " +
    "efficiency against the chosen image, variance of the mean); + − exposure, 0 reset, s sRGB; " +
    "[ ] the top of a map's range, { } its bottom; z fit. Wheel zooms (all images together), drag pans, " +
    "a click holds the readout on a pixel. Values are the 32-bit floats of the EXRs.");
  root.append(imageBar, viewBar, settingsBar, stage, scale);
  // The readout and the keys go beside the image, above the metrics table, where the page has one.
  const side = document.querySelector(".viewer-side");
  if (side) side.prepend(readout, keys);
  else root.append(readout, keys);

  // ------------------------------------------------------------------------------------------
  // Drawing: the current image or map into an offscreen canvas at one texel per pixel, then
  // onto the stage with the shared zoom and pan, nearest neighbour (no smoothing).

  const texture = document.createElement("canvas");
  texture.width = W;
  texture.height = H;
  const textureContext = texture.getContext("2d");
  const pixels = textureContext.createImageData(W, H);

  function encode(x) {
    // imagefiles.to_srgb8: exposure, clip to [0, 1], the sRGB curve (or none), 8 bits.
    x = Number.isNaN(x) ? 0 : Math.min(1, Math.max(0, x));
    if (state.srgb) x = x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
    return Math.round(x * 255);
  }

  function paintTexture() {
    const out = pixels.data;
    const map = viewMap(state.image);
    why.textContent = map && map.why ? map.why : "";
    if (map === null) {
      const mean = images[state.image].mean, gain = Math.pow(2, state.exposure);
      for (let p = 0; p < N; p++) {
        for (let c = 0; c < 3; c++) out[4 * p + c] = encode(mean[3 * p + c] * gain);
        out[4 * p + 3] = 255;
      }
    } else if (map.why) {
      out.fill(0);
    } else {
      const table = data.colormaps[data.views[state.view].colormap];
      const [low, high] = state.ranges[state.view];
      for (let p = 0; p < N; p++) {
        const v = map.values[p];
        const t = Number.isFinite(v) ? Math.min(255, Math.max(0, Math.floor(((v - low) / (high - low)) * 256))) : 0;
        const rgb = Number.isNaN(v) ? [128, 128, 128] : table[v === Infinity ? 255 : t];
        out[4 * p] = rgb[0];
        out[4 * p + 1] = rgb[1];
        out[4 * p + 2] = rgb[2];
        out[4 * p + 3] = 255;
      }
    }
    textureContext.putImageData(pixels, 0, 0);
  }

  function stageSize() {
    const width = Math.max(240, Math.min(root.clientWidth || 800, 960));
    const height = Math.max(200, Math.min(Math.round((width * H) / W), 560));
    return [width, height];
  }

  function layout() {
    const [width, height] = stageSize();
    const ratio = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
      canvas.style.width = width + "px";
      canvas.style.height = height + "px";
    }
    return [width, height, ratio];
  }

  function fitScale() {
    const [width, height] = stageSize();
    return Math.min(width / W, height / H);
  }

  function fit() {
    const [width, height] = layout();
    state.scale = fitScale();
    state.ox = (width - W * state.scale) / 2;
    state.oy = (height - H * state.scale) / 2;
    redraw(false);
  }

  function drawStage() {
    const ratio = layout()[2];
    const context = canvas.getContext("2d");
    context.setTransform(1, 0, 0, 1, 0, 0);
    context.fillStyle = "#1d1d1d";
    context.fillRect(0, 0, canvas.width, canvas.height);
    context.imageSmoothingEnabled = false;
    context.setTransform(ratio * state.scale, 0, 0, ratio * state.scale, ratio * state.ox, ratio * state.oy);
    context.drawImage(texture, 0, 0);
    const held = state.pinned;
    if (held && state.scale >= 4) {  // outline the held pixel once it is big enough to see
      context.lineWidth = 2 / state.scale;
      context.strokeStyle = "#0f0";
      context.strokeRect(held[0], held[1], 1, 1);
    }
  }

  function paintScale() {
    const view = data.views[state.view];
    scale.style.visibility = view ? "visible" : "hidden";
    rangeLow.disabled = rangeHigh.disabled = !view;
    if (!view) return;
    const table = data.colormaps[view.colormap];
    const context = scaleCanvas.getContext("2d");
    for (let t = 0; t < 256; t++) {
      context.fillStyle = `rgb(${table[t][0]},${table[t][1]},${table[t][2]})`;
      context.fillRect(t, 0, 1, scaleCanvas.height);
    }
    const [low, high] = state.ranges[state.view];
    scaleLow.textContent = format(low, 3);
    scaleHigh.textContent = format(high, 3);
    scaleLabel.textContent = view.label;
    rangeLow.value = low;
    rangeHigh.value = high;
  }

  // A pan or zoom only draws the stage and the readout again (it runs on every mouse move of a
  // drag); a change of image, view or setting also paints the texture and the controls.
  function redraw(repaint) {
    if (repaint) {
      paintTexture();
      refreshControls();
    }
    drawStage();
    showReadout();
  }

  function refreshControls() {
    paintScale();
    for (const button of imageBar.children) {
      button.classList.toggle("on", Number(button.dataset.index) === state.image);
    }
    for (const button of viewBar.children) button.classList.toggle("on", button.dataset.view === state.view);
    for (const row of document.querySelectorAll("table#metrics tr")) {  // the shown image's row
      row.classList.toggle("current", row.children[0].textContent === images[state.image].name);
    }
    exposureBox.value = state.exposure;
    srgbBox.checked = state.srgb;
    baselineBox.value = state.baseline;
    const image = images[state.image];
    const time = image.seconds === null ? "" : `, ${format(image.seconds, 3)} ${image.unit}`;
    const spp = image.spp === null ? "spp unknown" : `${image.spp} spp`;
    caption.textContent = `${state.image + 1}: ${image.name} (${spp}${time}) — ` +
      VIEWS.find((v) => v.id === state.view).title +
      (state.view === "image" ? `, exposure ${state.exposure >= 0 ? "+" : ""}${state.exposure}` : "");
  }

  // ------------------------------------------------------------------------------------------
  // The readout: every quantity at the held pixel, or the one under the cursor.

  function format(v, digits) {
    if (v === null || v === undefined || Number.isNaN(v)) return "n/a";
    if (!Number.isFinite(v)) return v > 0 ? "inf" : "-inf";
    const size = Math.abs(v);
    if (size !== 0 && (size < 1e-3 || size >= 1e6)) return v.toExponential(digits - 1);
    return Number(v.toPrecision(digits)).toString();
  }
  function triple(array, p) {
    return [0, 1, 2].map((c) => format(array[3 * p + c], 7)).join(" ");
  }

  function showReadout() {
    const at = state.pinned || state.hover;
    if (!at) {
      for (const cell of Object.values(cells)) cell.textContent = "";
      cells.pixel.textContent = "(point at the image)";
      return;
    }
    const [x, y] = at, p = y * W + x, i = state.image, image = images[i];
    const compared = i > 0;
    const error = [0, 1, 2].map((c) => image.mean[3 * p + c] - reference.mean[3 * p + c]);
    cells.pixel.textContent = `${x}, ${y}` + (state.pinned ? " (held)" : "");
    cells.image.textContent = image.name;
    cells.value.textContent = triple(image.mean, p);
    cells.reference.textContent = triple(reference.mean, p);
    cells.error.textContent = compared ? error.map((e) => format(e, 7)).join(" ") : "n/a";
    cells.relerr.textContent = compared ? format(relerr(i)[p], 7) : "n/a";
    cells.variance.textContent = image.variance ? triple(image.variance, p) : "n/a";
    cells.flip.textContent = image.flip ? format(image.flip[p], 7) : "n/a";
    const against = state.baseline;
    const timed = compared && against > 0 && against !== i && image.seconds > 0 && images[against].seconds > 0;
    cells.efficiency.textContent = timed
      ? `${format(efficiency(i, against)[p], 7)} (against ${images[against].name})` : "n/a";
  }

  function pixelAt(cx, cy) {
    // Stage coordinates (CSS pixels) -> the image pixel there, or null outside the image.
    const x = Math.floor((cx - state.ox) / state.scale), y = Math.floor((cy - state.oy) / state.scale);
    return x >= 0 && y >= 0 && x < W && y < H ? [x, y] : null;
  }

  // ------------------------------------------------------------------------------------------
  // Input.

  function setImage(i) {
    if (i < 0 || i >= images.length) return;
    state.image = i;
    redraw(true);
  }
  function setView(view) {
    state.view = view;
    redraw(true);
  }
  function setRange(end, value) {
    // One end of the current map's range; an empty or non-numeric entry, or one that would put
    // the ends in the wrong order, leaves it as it was. Rounded to 6 decimals, so that steps
    // of 0.05 do not show as 0.9500000000000001.
    const range = state.ranges[state.view];
    const number = value === "" ? NaN : Math.round(Number(value) * 1e6) / 1e6;
    if (range && Number.isFinite(number)) {
      const next = range.slice();
      next[end] = number;
      if (next[1] > next[0]) state.ranges[state.view] = next;
    }
    redraw(true);
  }
  function rangeStep() {
    const [low, high] = state.ranges[state.view];
    return state.view === "flip" ? 0.05 : Math.max(0.25, Math.round((high - low) / 8 * 4) / 4);
  }
  function zoomAbout(cx, cy, factor) {
    // At most 256 screen pixels per pixel, or 4 times the fit for an image smaller than that.
    const next = Math.min(Math.max(256, 4 * fitScale()), Math.max(0.05, state.scale * factor));
    state.ox = cx - ((cx - state.ox) * next) / state.scale;
    state.oy = cy - ((cy - state.oy) * next) / state.scale;
    state.scale = next;
    redraw(false);
  }

  let drag = null;
  canvas.addEventListener("wheel", (event) => {
    event.preventDefault();
    const box = canvas.getBoundingClientRect();
    zoomAbout(event.clientX - box.left, event.clientY - box.top, Math.pow(2, -event.deltaY / 240));
  }, {passive: false});
  canvas.addEventListener("mousedown", (event) => {
    drag = {x: event.clientX, y: event.clientY, ox: state.ox, oy: state.oy, moved: false};
  });
  window.addEventListener("mouseup", (event) => {
    if (drag && !drag.moved && event.target === canvas) {
      const box = canvas.getBoundingClientRect();
      const at = pixelAt(event.clientX - box.left, event.clientY - box.top);
      const same = state.pinned && at && state.pinned[0] === at[0] && state.pinned[1] === at[1];
      state.pinned = same ? null : at;
      redraw(false);
    }
    drag = null;
  });
  window.addEventListener("mousemove", (event) => {
    const box = canvas.getBoundingClientRect();
    if (drag) {
      const dx = event.clientX - drag.x, dy = event.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
      if (drag.moved) {
        state.ox = drag.ox + dx;
        state.oy = drag.oy + dy;
        redraw(false);
      }
      return;
    }
    if (event.target === canvas) {
      state.hover = pixelAt(event.clientX - box.left, event.clientY - box.top);
      showReadout();
    }
  });
  canvas.addEventListener("mouseleave", () => { state.hover = null; showReadout(); });

  document.addEventListener("keydown", (event) => {
    const target = event.target;
    if (event.ctrlKey || event.metaKey || event.altKey) return;
    if (target && (target.tagName === "INPUT" || target.tagName === "SELECT" || target.tagName === "TEXTAREA")) return;
    const box = stage.getBoundingClientRect();  // the keys are the viewer's only while it is in view
    if (box.bottom <= 0 || box.top >= window.innerHeight) return;
    const key = event.key;
    const view = VIEWS.find((v) => v.key === key.toLowerCase());
    const range = state.ranges[state.view];
    if (key >= "1" && key <= "9") setImage(Number(key) - 1);
    else if (key === "ArrowRight") setImage((state.image + 1) % images.length);
    else if (key === "ArrowLeft") setImage((state.image + images.length - 1) % images.length);
    else if (view) setView(view.id);
    else if (key === "+" || key === "=") { state.exposure += 0.5; redraw(true); }
    else if (key === "-" || key === "_") { state.exposure -= 0.5; redraw(true); }
    else if (key === "0") { state.exposure = data.exposure; redraw(true); }
    else if (key === "s" || key === "S") { state.srgb = !state.srgb; redraw(true); }
    else if (range && key === "]") setRange(1, range[1] + rangeStep());
    else if (range && key === "[") setRange(1, range[1] - rangeStep());
    else if (range && key === "}") setRange(0, range[0] + rangeStep());
    else if (range && key === "{") setRange(0, range[0] - rangeStep());
    else if (key === "z" || key === "Z") fit();
    else return;
    event.preventDefault();
  });
  window.addEventListener("resize", () => redraw(false));

  // ------------------------------------------------------------------------------------------
  // Sortable tables: a click on a column's head sorts by it (numbers by value from data-value,
  // n/a last either way), a second click reverses.

  function sortable(table) {
    const heads = Array.from(table.querySelectorAll("tr:first-child th"));
    heads.forEach((head, column) => head.addEventListener("click", () => {
      const order = head.dataset.order === "ascending" ? "descending" : "ascending";
      heads.forEach((h) => delete h.dataset.order);
      head.dataset.order = order;
      const rows = Array.from(table.querySelectorAll("tr")).slice(1);
      const key = (row) => {
        const cell = row.children[column];
        const v = cell.dataset.value;
        return v === undefined ? cell.textContent : v === "" ? null : Number(v);
      };
      const sign = order === "ascending" ? 1 : -1;
      rows.sort((a, b) => {
        const ka = key(a), kb = key(b);
        if (ka === null || kb === null) return (ka === null) - (kb === null);
        return (typeof ka === "number" && typeof kb === "number" ? ka - kb : String(ka).localeCompare(kb)) * sign;
      });
      const body = rows[0] ? rows[0].parentNode : table;
      for (const row of rows) body.append(row);
    }));
  }
  window.tracerViewer = {state, images, pixelAt, setImage, setView, fit, redraw};
  fit();
  redraw(true);
})();
