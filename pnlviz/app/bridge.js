// pnlviz's pointer bridge: the few things viser's client does not do for the image view.
//
// - Pan and zoom at display rate, in the page. The wheel, + and - zoom around the pointer, and a
//   plain left drag on the image (or the dark frame around it) pans it: the bridge moves the
//   viewer's canvas with a CSS transform (translate and scale of the element holding the WebGL
//   canvas; its parent clips it, so nothing covers the panel) at once, and sends nothing while the
//   hand moves. When the gesture ends (the wheel idle for 120 ms, the button released) it sends the
//   whole transform once, with the version of the view it was made on; the server moves the
//   camera there in one push and answers, in the same message batch as the camera, with the new
//   version (#pnlviz-view, pnlviz.app.pagesync). The bridge takes its transform off when that
//   answer arrives, so the real render replaces the CSS one in the same frame. A gesture ended
//   while the previous one is still unanswered is sent when the answer comes (rebased on it).
//   After a key with which the server moves the view (0: fit, 1: native; data-view-keys), what
//   the hand does before that view arrives is kept over it, and what it did before the key is not.
// - Pan or point drag? The server lists the grabbable points and the view in #pnlviz-view; a
//   press within the grab radius of one is left to viser (a point drag: a ring drawn here follows
//   the pointer at display rate while the server moves the point and recalibrates; the ring goes
//   at the release if the server's point is under it already, else when the server's points
//   arrive after the release). Any other plain left press is a pan
//   candidate: its pointer moves are kept from viser, so viser never starts a drag; past 3 px it
//   is a pan (viser's pending click is cancelled with a pointercancel), else the release goes on
//   to viser as a click (select, deselect; shift+click places, and is never taken).
// - Box selection: a ctrl (or cmd) drag from a place on the image with no point under it draws a
//   rectangle; at the release the rectangle goes to the server (fractions of the canvas as the
//   server renders it), which adds the keypoints inside it to the selection. A ctrl+click on a
//   point stays viser's (in or out of the selection).
// - The canvas at the device pixel ratio: viser lowers its resolution on a slow machine unless the
//   URL carries ?fixedDpr=<ratio> (read when the page starts), so a page whose URL carries
//   another ratio (or none) reloads once with its own window.devicePixelRatio.
// - The image view's dark frame around the image: the bridge paints the canvas's container in the
//   colour #pnlviz-bridge names (data-backdrop; the canvas is transparent), and takes it off in
//   the 3D view. A mesh there would be filled on every WebGL frame.
// - The arrow keys nudge the selected point by one image pixel (ten with shift) instead of turning
//   the camera. viser's own camera moves in the image view are done here too, as the page's pan
//   and zoom: a right (or middle) drag pans, W / S zoom, A / D / Q / E pan. viser's camera would
//   move the overlays without the frame the page draws behind them (pageframes.js).
// - In the image view the viewer's WebGL context skips its draw calls: everything seen there is
//   the page's, and software WebGL filled the scene's invisible pointer meshes on every frame.
// - Every <label for="..."> points at its input (viser labels inputs whose elements carry no id).
// - The keys work at the window level except while typing in a text field: Enter and Escape leave
//   a field; a dropdown gives the keyboard back once a choice is made, and its search starts from
//   an empty text (typing 45 finds 45, not 345); a key pressed on a checkbox, a button or a
//   closed dropdown goes to the window's hotkeys (viser's hotkeys ignore every <input>).
//
// The server talks to it through the attributes of elements of its own (#pnlviz-bridge:
// data-input, the label of the text field it writes to; data-mode, "image" or "3d"; #pnlviz-view:
// the view, see pnlviz/app/pagesync.py), and it talks to the server by writing JSON into that text
// field, which viser sends like a typed value. GUI values are throttled (the latest one wins), so
// what it sends is cumulative: the total nudge so far, the last gesture (until it is answered),
// where the pointer is, and the canvas size in CSS pixels.
// window.__pnlvizBridge exposes its state (gestures sent, input-to-frame latencies) to tests.
(() => {
  const config = () => {
    const el = document.getElementById("pnlviz-bridge");
    return el ? { input: el.dataset.input, mode: el.dataset.mode, backdrop: el.dataset.backdrop || "",
      viewKeys: el.dataset.viewKeys || "" } : null;
  };
  if (window.__pnlvizBridge) return; // one bridge per page, whatever re-renders the panel

  // ---- the device pixel ratio: once per tab, the page reloads with its own in the URL
  const dpr = String(window.devicePixelRatio || 1);
  const params = new URLSearchParams(window.location.search);
  if (params.get("fixedDpr") !== dpr) {
    if (sessionStorage.getItem("pnlviz-dpr") !== dpr) { // never in a loop
      sessionStorage.setItem("pnlviz-dpr", dpr);
      params.set("fixedDpr", dpr);
      window.__pnlvizBridge = { reloading: true };
      window.location.replace(`${window.location.pathname}?${params}${window.location.hash}`);
      return;
    }
  } else {
    sessionStorage.removeItem("pnlviz-dpr");
  }

  const IDENTITY = { s: 1.0, tx: 0.0, ty: 0.0 };
  const state = {
    logZoom: 0.0, nudgeX: 0, nudgeY: 0, seq: 0, x: 0.5, y: 0.5, over: false,
    T: { ...IDENTITY }, // the CSS transform on the canvas, over the view of version `base`
    base: -1, k: 0, sent: null, dirty: false, // the gesture in the air (unanswered), one waiting
    viewKey: 0, // a view key pressed (1 fit, 2 native), to go with the next gesture
    wheelTimer: null, idleMs: 120, press: null, point: null, swallowClick: false,
    view: null, gestures: 0, latency: [], pendingInputs: [], rafPending: false,
    boxPress: null, boxes: 0, box: null, // a ctrl+drag in the air; boxes drawn; the last one [k, x0, y0, x1, y1]
    relaying: false, // a move copied to the window's listeners is on its way (relayMove)
  };
  window.__pnlvizBridge = state;

  // the viewer's canvas: the WebGL one, which three.js marks (viser draws text into small canvases,
  // a 2D overlay of the same size may sit over it, and the page draws its overlays on another:
  // pageframes.js). `target`, its react-three-fiber wrapper, is moved by the transform; `clip`, the
  // wrapper's parent (overflow hidden, the canvas's size), holds it still and clips it
  const glCanvas = () => {
    let best = null;
    for (const c of document.querySelectorAll("canvas[data-engine]")) {
      if (!best || c.clientWidth * c.clientHeight > best.clientWidth * best.clientHeight) best = c;
    }
    return best;
  };
  state.glCanvas = glCanvas; // for the frame layer (pageframes.js), as are readView and imageMode
  const stage = () => {
    const canvas = glCanvas();
    if (!canvas || !canvas.parentElement || !canvas.parentElement.parentElement) return null;
    return { canvas, target: canvas.parentElement, clip: canvas.parentElement.parentElement };
  };

  const field = () => {
    const cfg = config();
    if (!cfg || !cfg.input) return null;
    const label = [...document.querySelectorAll("label")].find((l) => l.textContent.trim() === cfg.input);
    let row = label;
    while (row && !row.querySelector("input")) row = row.parentElement;
    const input = row ? row.querySelector("input") : null;
    if (row && row.parentElement && row.parentElement.style.display !== "none") {
      row.parentElement.style.display = "none"; // a channel, not a control
    }
    return input;
  };

  const send = () => {
    const input = field();
    if (!input) return;
    state.seq += 1;
    const canvas = glCanvas();
    const g = state.sent;
    const message = JSON.stringify({
      kind: "pointer", n: state.seq, log_zoom: state.logZoom, x: state.x, y: state.y,
      nudge: [state.nudgeX, state.nudgeY],
      canvas: canvas ? [canvas.clientWidth, canvas.clientHeight] : null,
      view: g ? [g.k, g.base, g.s, g.tx, g.ty, g.view] : null,
      box: state.box,
    });
    Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set.call(input, message);
    input.dispatchEvent(new Event("input", { bubbles: true }));
  };

  // a canvas of the viewer (there can be two of the same size, one over the other), not a small
  // one that draws text
  const canvasOf = (target) => {
    if (!target || target.tagName !== "CANVAS") return null;
    const view = glCanvas();
    const area = (c) => c.clientWidth * c.clientHeight;
    return view && area(target) >= 0.5 * area(view) ? target : null;
  };
  // where an event is on the canvas as it stands (CSS px from its top-left corner, untransformed)
  const local = (event) => {
    const st = stage();
    if (!st) return null;
    const box = st.clip.getBoundingClientRect();
    return [event.clientX - box.left, event.clientY - box.top, box.width, box.height];
  };
  const track = (event) => {
    if (state.relaying) return; // our copy of a move, sent to the window: the move itself was seen
    const canvas = canvasOf(event.target);
    state.over = canvas !== null;
    const p = canvas ? local(event) : null;
    if (!p) return;
    state.x = p[0] / p[2];
    state.y = p[1] / p[3];
  };
  window.addEventListener("pointermove", track, { capture: true, passive: true });
  const imageMode = () => {
    const cfg = config();
    return !!cfg && cfg.mode === "image";
  };
  state.imageMode = imageMode;

  // ---- the view as the server last told it (#pnlviz-view)
  const readView = () => {
    const el = document.getElementById("pnlviz-view");
    if (!el) return null;
    const d = el.dataset;
    const nums = (t) => (t ? t.split(",").map(Number) : []);
    return {
      v: Number(d.v), answer: Number(d.answer), applied: d.applied === "1", view: nums(d.view),
      limits: nums(d.limits), canvas: nums(d.canvas), reach: Number(d.reach || 0),
      pointsText: d.points || "", points: nums(d.points), frame: d.frame || "", ids: d.ids || "",
      idGap: Number(d.idGap || 0), draw: d.draw || "",
    };
  };
  state.readView = readView;

  // ---- the CSS transform: a canvas point p shows what the render has at (p - t) / s
  const isIdentity = (T) => Math.abs(T.s - 1) < 1e-9 && Math.abs(T.tx) < 1e-6 && Math.abs(T.ty) < 1e-6;
  const applyTransform = () => {
    const st = stage();
    if (!st) return;
    const T = state.T;
    if (isIdentity(T)) {
      st.target.style.transform = "";
    } else {
      st.target.style.transformOrigin = "0 0";
      st.target.style.transform = `translate(${T.tx}px, ${T.ty}px) scale(${T.s})`;
    }
    paintBackdrop();
  };
  // the image view's dark frame around the image: the page's background behind the (transparent)
  // canvas, not a mesh that every WebGL frame would fill; the 3D view keeps viser's
  const paintBackdrop = () => {
    const st = stage();
    const cfg = config();
    if (!st || !cfg) return;
    const colour = cfg.mode === "image" ? cfg.backdrop : "";
    if (st.clip.style.background !== colour) st.clip.style.background = colour;
    quietGl(st.canvas, cfg.mode === "image");
  };
  // In the image view WebGL draws nothing anyone sees (the image, the overlays and the ids are the
  // page's; the scene holds only invisible meshes that take the pointer, which three.js raycasts on
  // the CPU), yet software WebGL filled every one of them pixel by pixel on every frame viser drew.
  // There the viewer's context skips its draw calls, and its clears but the first (which wipes
  // what the 3D view left: the canvas is transparent from then on): a frame with neither leaves
  // the canvas as it is, so the browser composites nothing new for it (in software, a clear of the
  // whole canvas and its copy to the screen on every frame viser drew). The 3D view gets them back.
  const GL_DRAWS = ["drawArrays", "drawElements", "drawArraysInstanced", "drawElementsInstanced", "drawRangeElements"];
  const quietGl = (canvas, quiet) => {
    const gl = canvas.getContext("webgl2") || canvas.getContext("webgl");
    if (!gl || !!gl.pnlvizQuiet === quiet) return;
    gl.pnlvizQuiet = quiet;
    for (const k of GL_DRAWS) {
      if (quiet) gl[k] = () => {};
      else delete gl[k]; // the context's own method again
    }
    if (quiet) {
      let wiped = false;
      const clear = Object.getPrototypeOf(gl).clear;
      gl.clear = (mask) => {
        if (wiped || !(mask & gl.COLOR_BUFFER_BIT)) return;
        wiped = true;
        clear.call(gl, mask);
      };
    } else {
      delete gl.clear;
    }
  };
  // keep the transform within what the server allows: the zoom limits, the frame's centre on screen
  const clamp = (T) => {
    const d = state.view;
    if (!d || d.view.length !== 3 || d.limits.length !== 4 || d.canvas.length !== 2) return T;
    const [cu, cv, z] = d.view;
    const [zmin, zmax, W, H] = d.limits;
    const s = Math.min(Math.max(T.s, zmin / z), zmax / z);
    const fix = (c, t, C, size) => {
      const centre = c + ((1 - s) * C / 2 - t) / (s * z);
      const kept = Math.min(Math.max(centre, -0.5), size - 0.5);
      return (1 - s) * C / 2 - (kept - c) * s * z;
    };
    return { s, tx: fix(cu, T.tx, d.canvas[0], W), ty: fix(cv, T.ty, d.canvas[1], H) };
  };
  // an input moved the canvas: when the frame with the transform starts, its latency is noted
  const frameDrawn = (timeStamp) => {
    state.pendingInputs.push(timeStamp);
    if (state.rafPending) return;
    state.rafPending = true;
    requestAnimationFrame(() => {
      const now = performance.now();
      for (const t of state.pendingInputs) state.latency.push(now - t);
      if (state.latency.length > 2000) state.latency.splice(0, state.latency.length - 2000);
      state.pendingInputs = [];
      state.rafPending = false;
    });
  };
  const zoomAt = (logFactor, p, timeStamp) => {
    const T = state.T;
    const s = clamp({ ...T, s: T.s * Math.exp(logFactor) }).s;
    const f = s / T.s;
    state.T = clamp({ s, tx: f * (T.tx - p[0]) + p[0], ty: f * (T.ty - p[1]) + p[1] });
    applyTransform();
    frameDrawn(timeStamp);
    sendWhenIdle();
  };
  // the wheel's (or the keys') gesture goes to the server once they have rested for idleMs
  const sendWhenIdle = () => {
    clearTimeout(state.wheelTimer);
    state.wheelTimer = setTimeout(() => {
      state.wheelTimer = null;
      endGesture();
    }, state.idleMs);
  };
  // the view moved by (dx, dy) CSS px by a key (held: repeated); sent when the keys rest
  const panBy = (dx, dy, timeStamp) => {
    const T = state.T;
    state.T = clamp({ s: T.s, tx: T.tx + dx, ty: T.ty + dy });
    applyTransform();
    frameDrawn(timeStamp);
    sendWhenIdle();
  };
  // a gesture ended: its whole transform goes to the server, once (later if one is in the air)
  const endGesture = () => {
    if (state.wheelTimer !== null || (state.press && state.press.panning)) return; // not over yet
    if (state.sent) {
      state.dirty = true;
      return;
    }
    state.dirty = false;
    if ((isIdentity(state.T) && !state.viewKey) || state.base < 0) return;
    state.k += 1;
    // a view key goes as a gesture: the view that answers it is known by its number
    state.sent = { k: state.k, base: state.base, ...state.T, view: state.viewKey };
    state.viewKey = 0;
    state.gestures += 1;
    send();
  };
  // T with U taken off it (T = G after U: G), for a transform over another render
  const after = (T, U) => ({ s: T.s / U.s, tx: T.tx - (T.s / U.s) * U.tx, ty: T.ty - (T.s / U.s) * U.ty });
  // the server's answer: the render now shows the view the transform was sent for
  let seen = "";
  const onView = () => {
    if (!imageMode() && !isIdentity(state.T)) {
      state.T = { ...IDENTITY };
      applyTransform();
    }
    paintBackdrop();
    const el = document.getElementById("pnlviz-view");
    const key = el ? [el.dataset.v, el.dataset.answer, el.dataset.view, el.dataset.points, el.dataset.reach].join("|") : "";
    if (key === seen) return;
    seen = key;
    const d = readView();
    if (!d || !Number.isFinite(d.v)) return;
    const old = state.view;
    state.view = d;
    const g = state.sent;
    if (g && d.answer >= g.k) {
      // what is left of the transform over the new render (the hand may have gone on); a gesture
      // refused because another view came first was already taken off (below): the rest stays (a
      // view key is done whatever view came first: what the hand did since that view is kept)
      const applied = d.applied && d.answer === g.k;
      state.T = applied && !g.moved ? after(state.T, g) : g.moved ? state.T : { ...IDENTITY };
      state.sent = null;
      state.base = d.v;
      applyTransform();
      if (state.dirty || (g.moved && !isIdentity(state.T))) endGesture();
    } else if (d.v !== state.base) {
      // the server moved the view (a button, a frame of another size): its view rules
      state.base = d.v;
      state.T = { ...IDENTITY };
      if (g) g.moved = true; // made on the view before: the server refuses it (a view key: does it)
      applyTransform();
    }
    if (state.ring && state.ring.released && (!old || old.pointsText !== d.pointsText)) hideRing();
  };

  // ---- pan, or a point drag: told apart on the press
  const screenOf = (u, v) => {
    const d = state.view;
    const [cu, cv, z] = d.view;
    const T = state.T;
    return [T.s * (d.canvas[0] / 2 + (u - cu) * z) + T.tx, T.s * (d.canvas[1] / 2 + (v - cv) * z) + T.ty];
  };
  const viewKnown = () => {
    const d = state.view;
    return !!d && d.view.length === 3 && d.canvas.length === 2;
  };
  // the server's point nearest canvas point p within `reach` px (where it is on the canvas), or null
  const nearestPoint = (p, reach) => {
    const d = state.view;
    let best = null;
    let bestD = reach;
    for (let i = 0; i + 1 < d.points.length; i += 2) {
      const q = screenOf(d.points[i], d.points[i + 1]);
      const dist = Math.hypot(q[0] - p[0], q[1] - p[1]);
      if (dist <= bestD) {
        best = q;
        bestD = dist;
      }
    }
    return best;
  };
  const pointAt = (p) => {
    if (!viewKnown()) return undefined; // not known: viser decides
    return nearestPoint(p, Math.max(4, state.view.reach) * state.T.s);
  };
  const plainLeft = (e) => e.button === 0 && !e.shiftKey && !e.ctrlKey && !e.altKey && !e.metaKey;
  const ctrlLeft = (e) => e.button === 0 && !e.shiftKey && !e.altKey && (e.ctrlKey || e.metaKey);
  window.addEventListener(
    "pointerdown",
    (event) => {
      state.swallowClick = false;
      if (state.press) finishPress(); // its release never came (the window lost the pointer)
      if (state.boxPress) finishBox(false);
      if (imageMode() && (event.button === 1 || event.button === 2) && canvasOf(event.target)) {
        // a right (or middle) drag pans too, here: viser's camera would move the overlays alone,
        // without the frame the page draws behind them (pageframes.js)
        event.stopImmediatePropagation();
        state.press = { id: event.pointerId, x0: event.clientX, y0: event.clientY, x: event.clientX, y: event.clientY,
                        panning: false, mask: event.button === 2 ? 2 : 4 };
        return;
      }
      const plain = plainLeft(event);
      if (!imageMode() || !(plain || ctrlLeft(event)) || !canvasOf(event.target)) return;
      const p = local(event);
      if (!p) return;
      const point = pointAt(p);
      if (point === undefined) return;
      if (!plain) { // ctrl+press: on a point, viser's ctrl+click; elsewhere a box candidate
        if (!point) state.boxPress = { id: event.pointerId, x0: event.clientX, y0: event.clientY, el: null };
        return;
      }
      if (point) {
        state.point = { id: event.pointerId, x0: event.clientX, y0: event.clientY, at: point, box: [p[0], p[1]] };
        return;
      }
      state.press = { id: event.pointerId, x0: event.clientX, y0: event.clientY, x: event.clientX, y: event.clientY,
                      panning: false, mask: 1 };
    },
    { capture: true },
  );
  const cancelViser = (pointerId) => {
    // viser's pending click or drag on the image: called off (it saw no move, so it started nothing)
    state.cancelling = true;
    try {
      window.dispatchEvent(new PointerEvent("pointercancel", { pointerId, isPrimary: true }));
    } finally {
      state.cancelling = false;
    }
  };
  window.addEventListener(
    "pointermove",
    (event) => {
      if (state.relaying) return; // our own copy of a move, on its way to the window's listeners
      const press = state.press;
      if (press && event.pointerId === press.id && !(event.buttons & press.mask)) finishPress(); // released unseen
      else if (press && event.pointerId === press.id) {
        event.stopImmediatePropagation(); // viser sees no move: no drag of the image starts
        if (!press.panning && Math.max(Math.abs(event.clientX - press.x0), Math.abs(event.clientY - press.y0)) > 3) {
          press.panning = true;
          cancelViser(press.id);
        }
        if (press.panning) {
          const T = state.T;
          state.T = clamp({ s: T.s, tx: T.tx + event.clientX - press.x, ty: T.ty + event.clientY - press.y });
          applyTransform();
          frameDrawn(event.timeStamp);
        }
        press.x = event.clientX;
        press.y = event.clientY;
        return;
      }
      const bp = state.boxPress;
      if (bp && event.pointerId === bp.id) {
        if (!(event.buttons & 1)) {
          finishBox(false); // released unseen
          return;
        }
        event.stopImmediatePropagation(); // viser sees no move: the camera does not turn
        if (!bp.el && Math.max(Math.abs(event.clientX - bp.x0), Math.abs(event.clientY - bp.y0)) > 3) {
          cancelViser(bp.id);
          bp.el = document.createElement("div");
          bp.el.id = "pnlviz-box";
          bp.el.style.cssText = "position:fixed;border:1px dashed #fff;outline:1px solid rgba(0,0,0,.6);" +
            "background:rgba(0,200,255,.12);pointer-events:none;z-index:1000";
          document.body.appendChild(bp.el);
        }
        if (bp.el) {
          const [x, y] = [Math.min(bp.x0, event.clientX), Math.min(bp.y0, event.clientY)];
          Object.assign(bp.el.style, { left: `${x}px`, top: `${y}px`, width: `${Math.abs(event.clientX - bp.x0)}px`,
                                       height: `${Math.abs(event.clientY - bp.y0)}px` });
          bp.x = event.clientX;
          bp.y = event.clientY;
        }
        return;
      }
      const pt = state.point;
      if (pt && event.pointerId === pt.id) {
        const dx = event.clientX - pt.x0;
        const dy = event.clientY - pt.y0;
        if (state.ring || Math.max(Math.abs(dx), Math.abs(dy)) > 3) {
          showRing(event.clientX - pt.box[0] + pt.at[0], event.clientY - pt.box[1] + pt.at[1]);
          frameDrawn(event.timeStamp);
        }
      }
      if (imageMode() && canvasOf(event.target)) relayMove(event);
    },
    { capture: true },
  );
  // In the image view a move over the canvas goes to the window's listeners only (viser's point
  // drags and their start), not to the scene's: three.js's hover would light the invisible
  // surfaces that take the clicks (viser outlines a hovered clickable mesh in yellow: zoomed in,
  // the surface over the frame washed the whole view) and viser's camera would see the moves.
  const relayMove = (event) => {
    event.stopImmediatePropagation();
    state.relaying = true;
    try {
      window.dispatchEvent(new PointerEvent(event.type, event));
    } finally {
      state.relaying = false;
    }
  };
  // a pan's press is over: its gesture goes to the server; true if it was a pan
  const finishPress = () => {
    const press = state.press;
    state.press = null;
    if (press && press.panning) endGesture();
    return !!(press && press.panning);
  };
  window.addEventListener("blur", () => {
    finishPress();
    finishBox(false);
  });
  // a ctrl+drag is over: with ``send``, the box (fractions of the canvas as the server renders it,
  // the page's transform undone) goes to the server, which selects the keypoints inside it
  const finishBox = (send_) => {
    const bp = state.boxPress;
    state.boxPress = null;
    if (!bp || !bp.el) return false;
    bp.el.remove();
    const st = stage();
    if (!send_ || !st) return true;
    const r = st.clip.getBoundingClientRect();
    const T = state.T;
    const frac = (cx, cy) => [(cx - r.left - T.tx) / T.s / r.width, (cy - r.top - T.ty) / T.s / r.height];
    const [a, b] = [frac(bp.x0, bp.y0), frac(bp.x, bp.y)];
    state.boxes += 1;
    state.box = [state.boxes, Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[0], b[0]), Math.max(a[1], b[1])];
    send();
    return true;
  };
  const released = (event) => {
    if (state.cancelling) return;
    const bp = state.boxPress;
    if (bp && event.pointerId === bp.id && finishBox(event.type === "pointerup")) {
      event.stopImmediatePropagation(); // viser's click was called off when the box started
      state.swallowClick = event.type === "pointerup";
    }
    const press = state.press;
    if (press && event.pointerId === press.id && finishPress()) {
      event.stopImmediatePropagation(); // viser's click was called off at the start of the pan
      state.swallowClick = event.type === "pointerup";
    }
    const pt = state.point;
    if (pt && event.pointerId === pt.id) {
      state.point = null;
      if (state.ring) {
        // it goes now if the server's point is under it already (the live preview caught up with
        // the hand), else when the server's points come (or after a while)
        state.ring.released = true;
        if (pointUnderRing()) hideRing();
        else setTimeout(hideRing, 1500);
      }
    }
  };
  window.addEventListener("pointerup", released, { capture: true });
  window.addEventListener("pointercancel", released, { capture: true });
  window.addEventListener(
    "click",
    (event) => {
      if (!state.swallowClick) return;
      state.swallowClick = false;
      event.stopImmediatePropagation();
    },
    { capture: true },
  );
  // the ring that follows the hand while a point is dragged (the server's point follows later)
  const showRing = (x, y) => {
    if (!state.ring) {
      const el = document.createElement("div");
      el.id = "pnlviz-drag-ring";
      el.style.cssText = "position:fixed;width:22px;height:22px;margin:-13px 0 0 -13px;border:2px solid #fff;" +
        "border-radius:50%;box-shadow:0 0 0 1px #000, inset 0 0 0 1px #000;pointer-events:none;z-index:1000";
      document.body.appendChild(el);
      state.ring = { el, released: false };
    }
    state.ring.el.style.left = `${x}px`;
    state.ring.el.style.top = `${y}px`;
    state.ring.x = x;
    state.ring.y = y;
  };
  // whether one of the server's points is drawn where the ring is (within 1.5 px: the pointer's
  // whole-pixel coordinates and the points' tenth-pixel ones put it 0.7-0.8 px off when it is)
  const pointUnderRing = () => {
    const st = stage();
    if (!st || !state.ring || !viewKnown()) return false;
    const box = st.clip.getBoundingClientRect();
    return nearestPoint([state.ring.x - box.left, state.ring.y - box.top], 1.5) !== null;
  };
  const hideRing = () => {
    if (state.ring && state.ring.released) {
      state.ring.el.remove();
      state.ring = null;
    }
  };

  const ARROWS = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
  // viser's camera keys, in the image view: A / D pan left / right, Q / E down / up (the frame
  // moves the other way), W / S zoom in / out around the canvas's centre: [dx, dy, zoom]
  const CAMERA_KEYS = { KeyA: [1, 0, 0], KeyD: [-1, 0, 0], KeyQ: [0, -1, 0], KeyE: [0, 1, 0], KeyW: [0, 0, 1], KeyS: [0, 0, -1] };
  const KEY_PAN_PX = 40;
  window.addEventListener(
    "wheel",
    (event) => {
      if (!imageMode() || !canvasOf(event.target)) return;
      event.preventDefault();
      event.stopImmediatePropagation();
      track(event);
      const p = local(event);
      if (!p) return;
      const lines = event.deltaMode === 1 ? 16 : event.deltaMode === 2 ? 400 : 1;
      zoomAt(-0.0015 * event.deltaY * lines, p, event.timeStamp); // one notch (100 px) ~ x1.16
    },
    { capture: true, passive: false },
  );
  // ---- the keyboard: in a text field only while typing
  const NOT_TEXT = new Set(["checkbox", "radio", "range", "button", "submit", "reset", "color", "file"]);
  const isCombobox = (t) => t && t.tagName === "INPUT" && t.getAttribute("aria-haspopup") === "listbox";
  const isOpen = (t) => t.getAttribute("aria-expanded") === "true";
  const typingIn = (t) =>
    !!t && (t.tagName === "TEXTAREA" || t.isContentEditable ||
      (t.tagName === "INPUT" && !t.readOnly && !NOT_TEXT.has(t.type) && (!isCombobox(t) || isOpen(t))));
  const release = () => {
    const t = document.activeElement;
    if (t && t !== document.body && typeof t.blur === "function") t.blur();
  };
  // a choice made in a dropdown: the keyboard goes back to the window
  window.addEventListener(
    "click",
    (event) => {
      if (event.target && event.target.closest && event.target.closest("[role=option]")) setTimeout(release, 0);
    },
    { capture: true },
  );
  // a dropdown's search starts empty, so typing replaces the shown choice instead of adding to it
  window.addEventListener(
    "focusin",
    (event) => {
      const t = event.target;
      if (isCombobox(t) && !t.readOnly && typeof t.select === "function") setTimeout(() => t.select(), 0);
    },
    { capture: true },
  );
  window.addEventListener(
    "keydown",
    (event) => {
      const t = event.target;
      if (typingIn(t)) {
        if (event.key === "Escape" || (event.key === "Enter" && !isCombobox(t))) release();
        else if (event.key === "Enter") {
          // the dropdown takes its choice first; with none highlighted, its first match
          const list = document.getElementById(t.getAttribute("aria-controls") || "");
          const options = list ? [...list.querySelectorAll("[role=option]")] : [];
          if (options.length && !options.some((o) => o.hasAttribute("data-combobox-selected"))) {
            event.preventDefault();
            event.stopImmediatePropagation();
            options[0].click();
          }
          setTimeout(release, 0);
        }
        return;
      }
      if (t && t.tagName === "INPUT" && !["Tab", " ", "Enter"].includes(event.key)) {
        // a checkbox, a button, a closed dropdown has the focus: the key is the window's
        release();
        if (!(event.key in ARROWS)) {
          event.preventDefault();
          event.stopImmediatePropagation();
          const again = new KeyboardEvent("keydown", {
            key: event.key, code: event.code, shiftKey: event.shiftKey, ctrlKey: event.ctrlKey,
            metaKey: event.metaKey, altKey: event.altKey, bubbles: true, cancelable: true,
          });
          document.body.dispatchEvent(again);
          return;
        }
      }
      const cfg = config();
      if (!cfg || cfg.mode !== "image" || event.ctrlKey || event.metaKey || event.altKey) return;
      if (event.key.length === 1 && cfg.viewKeys.includes(event.key)) {
        // fit or native resolution, sent as a gesture that ends here (a zoom still resting goes
        // with it): what the hand does from here is kept over the view that answers it
        event.preventDefault();
        event.stopImmediatePropagation();
        if (event.repeat) return;
        state.viewKey = cfg.viewKeys.indexOf(event.key) + 1;
        clearTimeout(state.wheelTimer);
        state.wheelTimer = null;
        endGesture();
        return;
      }
      if (event.key in ARROWS) {
        // nudge the selected point (instead of turning the camera, which the image view does not do)
        const step = event.shiftKey ? 10 : 1;
        state.nudgeX += step * ARROWS[event.key][0];
        state.nudgeY += step * ARROWS[event.key][1];
        event.preventDefault();
        event.stopImmediatePropagation();
        send();
        return;
      }
      if (event.code in CAMERA_KEYS) {
        // viser's camera keys, done here (they would move the overlays without the frame behind)
        const [dx, dy, zoom] = CAMERA_KEYS[event.code];
        event.preventDefault();
        event.stopImmediatePropagation();
        const st = stage();
        if (!st) return;
        const box = st.clip.getBoundingClientRect();
        if (zoom) zoomAt(zoom * Math.log(Math.SQRT2) / 2, [box.width / 2, box.height / 2], event.timeStamp);
        else panBy(dx * KEY_PAN_PX, dy * KEY_PAN_PX, event.timeStamp);
        return;
      }
      if (event.key !== "+" && event.key !== "=" && event.key !== "-" && event.key !== "_") return;
      if (!state.over) {
        state.x = 0.5;
        state.y = 0.5;
      }
      const st = stage();
      if (st) {
        const box = st.clip.getBoundingClientRect();
        const up = event.key === "+" || event.key === "=";
        zoomAt((up ? 1 : -1) * Math.log(Math.SQRT2), [state.x * box.width, state.y * box.height], event.timeStamp);
      }
      event.preventDefault();
    },
    { capture: true },
  );

  // <label for> without its element: point it at the input of its row, or (a row of buttons, which
  // name themselves) drop the "for".
  const mendLabels = () => {
    for (const label of document.querySelectorAll("label[for]")) {
      const id = label.getAttribute("for");
      if (!id || document.getElementById(id)) continue;
      const controls = "input, select, textarea, [role=slider], [role=switch], [role=combobox]";
      let row = label.parentElement;
      for (let up = 0; row && up < 2 && !row.querySelector(controls); up++) row = row.parentElement;
      const target = row ? row.querySelector(controls) : null;
      label.setAttribute("data-viser-for", id); // what viser named it
      if (!target) label.removeAttribute("for");
      else if (target.id) label.setAttribute("for", target.id); // it has an id of its own: point there
      else target.id = id;
    }
  };
  // viser's "Software WebGL rendering detected" notice stays until closed and covers the image on
  // every load of a machine without a GPU (most annotation VMs): closed as it appears (once per page)
  const closeSoftwareNotice = () => {
    for (const note of document.querySelectorAll(".mantine-Notification-root")) {
      if (!(note.textContent || "").includes("Software WebGL rendering")) continue;
      const close = note.querySelector(".mantine-Notification-closeButton");
      if (close) {
        close.click();
        state.softwareNoticeClosed = (state.softwareNoticeClosed || 0) + 1;
      }
    }
  };
  // the frame's title stays at the top of the panel while it scrolls (editing points far below it)
  const pinTitle = () => {
    const anchor = document.getElementById("pnlviz-title");
    if (!anchor || anchor.dataset.pinned) return;
    // the title's row: the ancestor beside the panel's other rows
    let row = anchor;
    while (row.parentElement && row.parentElement.children.length < 3) row = row.parentElement;
    if (!row.parentElement || row === document.body) return;
    // up to the panel's scrolling viewport, a box that hides its overflow would hold the row (a
    // sticky element sticks to its nearest clipping box): clipped without scrolling instead
    const scrolls = (el) => ["auto", "scroll"].includes(getComputedStyle(el).overflowY);
    let el = row.parentElement;
    for (; el && el !== document.body && !scrolls(el); el = el.parentElement) {
      if (getComputedStyle(el).overflowY === "hidden") el.style.overflow = "clip";
    }
    if (!el || el === document.body) return;
    let bg = "rgba(0, 0, 0, 0)";
    for (let up = row.parentElement; up && (bg === "rgba(0, 0, 0, 0)" || bg === "transparent"); up = up.parentElement) {
      bg = getComputedStyle(up).backgroundColor;
    }
    Object.assign(row.style, { position: "sticky", top: "0", zIndex: "3", background: bg });
    anchor.dataset.pinned = "1";
  };
  // the busy cue: the server flags an action running longer than 150 ms (#pnlviz-busy); a badge
  // over the image's top-left corner, where the eyes are, until it is done
  const showBusy = () => {
    const flag = document.getElementById("pnlviz-busy");
    const busy = !!flag && flag.dataset.busy === "1";
    let cue = document.getElementById("pnlviz-busy-cue");
    if (!busy) {
      if (cue) cue.style.display = "none";
      state.busy = false;
      return;
    }
    const canvas = glCanvas();
    if (!canvas) return;
    if (!cue) {
      cue = document.createElement("div");
      cue.id = "pnlviz-busy-cue";
      cue.textContent = "working\u2026";
      Object.assign(cue.style, { position: "fixed", zIndex: "1000", padding: "4px 10px", borderRadius: "12px",
        background: "rgba(20, 20, 20, 0.8)", color: "#ffd24a", font: "600 13px sans-serif", pointerEvents: "none" });
      document.body.appendChild(cue);
    }
    const box = canvas.getBoundingClientRect();
    Object.assign(cue.style, { left: `${box.left + 12}px`, top: `${box.top + 12}px`, display: "block" });
    if (!state.busy) state.busyShown = (state.busyShown || 0) + 1;
    state.busy = true;
  };
  mendLabels();
  onView();
  closeSoftwareNotice();
  pinTitle();
  showBusy();
  new MutationObserver(() => {
    mendLabels();
    closeSoftwareNotice();
    pinTitle();
    showBusy();
    onView(); // the server's view: an answer takes the transform off before this frame is drawn
  }).observe(document.body, { childList: true, subtree: true, attributes: true, attributeFilter: ["data-v", "data-points", "data-answer"] });
  // the canvas size in CSS pixels (the screen pixels a zoom is measured in; viser reports the
  // drawing buffer's, which shrinks when it lowers the resolution on a slow machine)
  const watchCanvas = () => {
    const canvas = glCanvas();
    if (!canvas || !canvas.clientWidth || !field()) return setTimeout(watchCanvas, 200);
    new ResizeObserver(() => send()).observe(canvas);
  };
  watchCanvas();
})();
