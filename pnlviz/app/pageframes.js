// pnlviz's frame layer: the frame's pixels drawn by the page, behind viser's transparent WebGL
// canvas (pnlviz/app/pageframes.py says why: in software WebGL the image plane cost 37-40 ms of
// every frame the browser drew).
//
// - The pixels: hidden panel elements of class pnlviz-frame, one per slot (data-slot, data-n: the
//   version of its pixels, data-size: "W,H", data-src: a JPEG data URL). Each version is decoded
//   once, off screen, as it arrives; a frame sent ahead is ready when it is shown.
// - What to show and where: #pnlviz-view (pnlviz/app/pagesync.py): data-frame "slot,version",
//   data-view the image pixel at the canvas centre and the zoom (CSS px per image px), data-canvas
//   the canvas size the server computed with. The WebGL camera looks straight at the image with a
//   fixed vertical field of view, so the canvas's real height scales the zoom. An image spans
//   pixels -0.5 .. W - 0.5 (integer coordinates are pixel centres).
// - The overlays are the page's too (#pnlviz-view data-draw: pnlviz/app/pagedraw.py says the
//   format): drawn on a 2D canvas over viser's, in CSS px at the view. viser's scene holds only
//   invisible surfaces that take the pointer, so a new frame, its overlays and its ids are all
//   shown as their message batch arrives, together (a frame whose pixels are still decoding is
//   shown with its overlays once they are), as is a view change (a pan's answer, as the bridge's
//   transform comes off).
// - The layer sits in the element the pointer bridge moves with its CSS transform (bridge.js), so
//   a pan or zoom in the page moves the image with the overlays; it takes no pointer events.
// - Shown in the image view only (#pnlviz-bridge data-mode).
// - The keypoints' ids are the page's too, in a layer over the canvas (#pnlviz-view data-ids:
//   "text,u,v;..." in image pixels, most important first). An id closer than data-id-gap CSS px
//   on screen to one before it is hidden, at every zoom (tests/test_app_browser_frames.py checks
//   the rule).
// window.__pnlvizFrames exposes its state (slots decoded, swaps, what is shown) to tests.
(() => {
  if (window.__pnlvizFrames || !window.__pnlvizBridge || window.__pnlvizBridge.reloading) return;
  const state = {
    slots: new Map(), shown: "", decoded: 0, swaps: 0, layer: null, placed: "",
    idsLayer: null, idsPlaced: "", drawLayer: null, drawPlaced: "",
  };
  window.__pnlvizFrames = state;

  const bridge = window.__pnlvizBridge;
  const glCanvas = () => bridge.glCanvas(); // the WebGL canvas, as the bridge finds it
  // a layer of ours in the canvas's wrapper (the element the bridge moves with its pans and zooms),
  // made again if the wrapper changes: `key` names it in `state`, `zIndex` -1 puts it under the
  // canvas (first child; the wrapper becomes a stacking context, so the layer is still drawn over
  // the page's background), 1 over it; `made(el)` fills a new one
  const ensureLayer = (key, id, zIndex, style, made) => {
    const canvas = glCanvas();
    if (!canvas || !canvas.parentElement) return null;
    const target = canvas.parentElement;
    if (!state[key] || state[key].parentElement !== target) {
      const el = document.createElement("div");
      el.id = id;
      Object.assign(el.style, { position: "absolute", left: "0", top: "0", width: "0", height: "0",
        zIndex: String(zIndex), pointerEvents: "none", overflow: "visible", ...style });
      if (zIndex < 0) {
        if (getComputedStyle(target).position === "static") target.style.position = "relative";
        target.style.zIndex = "0";
        target.insertBefore(el, target.firstChild);
      } else {
        target.appendChild(el);
      }
      state[key] = el;
      made(el);
    }
    return state[key];
  };
  // the frame's layer, under the canvas
  const layer = () => ensureLayer("layer", "pnlviz-frames", -1, {}, (el) => {
    state.placed = "";
    for (const s of state.slots.values()) el.appendChild(s.img);
  });
  // the overlays' layer, over the canvas: one 2D canvas
  const drawLayer = () => ensureLayer("drawLayer", "pnlviz-draw", 1, {}, (el) => {
    const c = document.createElement("canvas");
    Object.assign(c.style, { position: "absolute", left: "0", top: "0" });
    el.appendChild(c);
    state.drawPlaced = "";
  });
  // the ids' layer, over the overlays
  const idsLayer = () => ensureLayer("idsLayer", "pnlviz-ids", 2,
    { font: "600 11px/13px sans-serif", color: "#1a1a1a" }, () => {
      state.idsPlaced = "";
    });

  // the ids of `text` ("text,u,v;...") placed for the view (cu, cv) at z CSS px per image px; the
  // anchor of each is its bottom-left corner, a little off the point
  const placeIds = (text, gap, cu, cv, z, Wa, Ha) => {
    const l = idsLayer();
    if (!l) return;
    const key = [text, gap, cu, cv, z, Wa, Ha].join("|");
    if (key === state.idsPlaced) return;
    state.idsPlaced = key;
    const entries = text ? text.split(";").map((e) => e.split(",")) : [];
    const kept = [];
    entries.forEach(([label, u, v], i) => {
      const x = Wa / 2 + (Number(u) - cu) * z;
      const y = Ha / 2 + (Number(v) - cv) * z;
      const show = kept.every(([a, b]) => Math.hypot(a - x, b - y) >= gap);
      if (show) kept.push([x, y]);
      let el = l.children[i];
      if (!el) {
        el = document.createElement("span");
        Object.assign(el.style, { position: "absolute", left: "0", top: "0", padding: "0 2px", whiteSpace: "nowrap",
          background: "rgba(255, 255, 255, 0.85)", borderRadius: "2px" });
        l.appendChild(el);
      }
      if (el.textContent !== label) el.textContent = label;
      el.style.opacity = label.endsWith("?") ? "0.7" : "1"; // a ghost's id, as its disc, is fainter
      el.style.transform = `translate(${(x + 3).toFixed(1)}px, ${(y - 3).toFixed(1)}px) translateY(-100%)`;
      el.style.display = show ? "block" : "none";
    });
    for (let i = entries.length; i < l.children.length; i += 1) l.children[i].style.display = "none";
  };

  // the marks of `text` (pnlviz/app/pagedraw.py) drawn for the view (cu, cv) at z CSS px per image
  // px on a canvas of Wa x Ha CSS px: points in image pixels, sizes and widths in CSS px
  const placeDraw = (text, cu, cv, z, Wa, Ha) => {
    const l = drawLayer();
    if (!l) return;
    const key = [cu, cv, z, Wa, Ha, text].join("|");
    if (key === state.drawPlaced) return;
    state.drawPlaced = key;
    const c = l.firstChild;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(Wa * dpr);
    const h = Math.round(Ha * dpr);
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
      Object.assign(c.style, { width: `${Wa}px`, height: `${Ha}px` });
    }
    const g = c.getContext("2d");
    g.setTransform(1, 0, 0, 1, 0, 0);
    g.clearRect(0, 0, w, h);
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.lineCap = "round";
    for (const part of text ? text.split("|") : []) {
      const [kind, size, width, hex, alpha, coords] = part.split(";");
      const n = coords.split(",").map(Number);
      const s = Number(size);
      g.globalAlpha = Number(alpha);
      g.lineWidth = Number(width);
      g.strokeStyle = g.fillStyle = `#${hex}`;
      g.beginPath();
      const step = kind === "s" ? 4 : 2;
      for (let i = 0; i + step <= n.length; i += step) {
        const x = Wa / 2 + (n[i] - cu) * z;
        const y = Ha / 2 + (n[i + 1] - cv) * z;
        if (kind === "s") {
          g.moveTo(x, y);
          g.lineTo(Wa / 2 + (n[i + 2] - cu) * z, Ha / 2 + (n[i + 3] - cv) * z);
        } else if (kind === "q") {
          g.rect(x - s, y - s, 2 * s, 2 * s);
        } else {
          g.moveTo(x + s, y);
          g.arc(x, y, s, 0, 2 * Math.PI);
        }
      }
      if (kind === "d") g.fill();
      else g.stroke();
    }
    g.globalAlpha = 1;
  };

  // new pixels in a slot: decoded off screen; the slot's previous image stays until then
  const readSlots = () => {
    for (const el of document.querySelectorAll(".pnlviz-frame")) {
      const slot = el.dataset.slot;
      const n = el.dataset.n;
      const old = state.slots.get(slot);
      if (old && old.n === n) continue;
      const img = new Image();
      Object.assign(img.style, { position: "absolute", display: "none", maxWidth: "none", userSelect: "none" });
      img.draggable = false;
      img.alt = "";
      img.dataset.slot = slot;
      const [W, H] = (el.dataset.size || "0,0").split(",").map(Number);
      const entry = { n, img, W, H, ready: false };
      state.slots.set(slot, entry);
      img.src = el.dataset.src;
      img.decode().catch(() => {}).then(() => {
        if (state.slots.get(slot) !== entry) return; // replaced while decoding
        entry.ready = true;
        state.decoded += 1;
        const l = layer();
        if (!l) return;
        for (const other of [...l.children]) if (other.dataset.slot === slot) other.remove(); // the slot's older pixels
        l.appendChild(img);
        update();
      });
    }
  };

  const update = () => {
    const d = bridge.readView(); // #pnlviz-view, as the bridge reads it
    const canvas = glCanvas();
    if (!d || !canvas) return;
    const [cu, cv, zoom] = d.view;
    const Hs = d.canvas[1];
    const imageMode = bridge.imageMode();
    const viewOk = imageMode && Number.isFinite(zoom) && Hs > 0;
    const Wa = canvas.clientWidth;
    const Ha = canvas.clientHeight;
    const z = viewOk ? zoom * Ha / Hs : 0;
    for (const l of [drawLayer(), idsLayer()]) if (l) l.style.display = viewOk ? "block" : "none";
    const [slot, n] = d.frame.split(",");
    const entry = state.slots.get(slot);
    const ready = viewOk && entry && entry.ready && entry.n === n ? entry : null;
    if (ready) {
      // with their frame: a frame not decoded yet keeps the last one shown, and its overlays
      placeDraw(d.draw, cu, cv, z, Wa, Ha);
      placeIds(d.ids, d.idGap, cu, cv, z, Wa, Ha);
    }
    placeFrame(ready, slot, n, imageMode, cu, cv, z, Wa, Ha);
  };

  // `entry`: the frame's slot, decoded and in view (null: not yet)
  const placeFrame = (entry, slot, n, imageMode, cu, cv, z, Wa, Ha) => {
    const l = layer();
    if (!l) return;
    if (!entry) {
      // not decoded yet: what was shown stays (a frame not sent ahead shows once it is decoded)
      if (!imageMode) {
        for (const s of state.slots.values()) s.img.style.display = "none";
        state.placed = ""; // placed again when the image view comes back
      }
      return;
    }
    const key = [slot, n, cu, cv, z, Wa, Ha].join("|");
    if (key === state.placed) return;
    const shown = `${slot},${n}`;
    state.placed = key;
    // a transform, not left/top/width/height: the browser snaps a box's edges to whole pixels
    // (half a pixel off the overlays), not a transformed image's
    Object.assign(entry.img.style, {
      left: "0", top: "0", width: `${entry.W}px`, height: `${entry.H}px`, transformOrigin: "0 0",
      transform: `translate(${Wa / 2 + (-0.5 - cu) * z}px, ${Ha / 2 + (-0.5 - cv) * z}px) scale(${z})`,
      display: "block",
    });
    for (const s of state.slots.values()) if (s !== entry) s.img.style.display = "none";
    if (shown !== state.shown) {
      state.shown = shown;
      state.swaps += 1;
    }
  };

  const onMutation = () => {
    readSlots();
    update();
  };
  onMutation();
  new MutationObserver(onMutation).observe(document.body, {
    childList: true, subtree: true, attributes: true,
    attributeFilter: ["data-frame", "data-view", "data-mode", "data-ids", "data-id-gap", "data-draw"],
  });
  const watch = () => {
    const canvas = glCanvas();
    if (!canvas) return setTimeout(watch, 200);
    new ResizeObserver(() => update()).observe(canvas);
  };
  watch();
})();
