// pnlviz's pointer bridge: the few things viser's client does not do for the image view.
//
// - The mouse wheel and the + / - keys zoom around the pointer (viser's camera dollies towards the
//   centre of the view). In the image view the wheel is taken before the camera controls see it;
//   the zoom is sent to the server, which moves the camera (pnlviz.app.bridge).
// - The arrow keys nudge the selected point by one image pixel (ten with shift) instead of turning
//   the camera.
// - Every <label for="..."> points at its input (viser labels inputs whose elements carry no id).
// - The keys work at the window level except while typing in a text field: Enter and Escape leave
//   a field; a dropdown gives the keyboard back once a choice is made, and its search starts from
//   an empty text (typing 45 finds 45, not 345); a key pressed on a checkbox, a button or a
//   closed dropdown goes to the window's hotkeys (viser's hotkeys ignore every <input>).
//
// The server talks to it through the attributes of an element of its own (#pnlviz-bridge:
// data-input, the uuid of the text field it writes to; data-mode, "image" or "3d"), and it talks
// to the server by writing JSON into that text field, which viser sends like a typed value.
// GUI values are throttled (the latest one wins), so what it sends is cumulative: the total
// log-zoom and nudge so far, where the pointer is, and the canvas size in CSS pixels.
(() => {
  const config = () => {
    const el = document.getElementById("pnlviz-bridge");
    return el ? { input: el.dataset.input, mode: el.dataset.mode } : null;
  };
  if (window.__pnlvizBridge) return; // one bridge per page, whatever re-renders the panel
  const state = { logZoom: 0.0, nudgeX: 0, nudgeY: 0, seq: 0, x: 0.5, y: 0.5, over: false };
  window.__pnlvizBridge = state;

  // the viewer's canvas: the largest one on the page (viser draws text into small ones too)
  const viewCanvas = () => {
    let best = null;
    for (const c of document.querySelectorAll("canvas")) {
      if (!best || c.clientWidth * c.clientHeight > best.clientWidth * best.clientHeight) best = c;
    }
    return best;
  };

  const field = () => {
    const cfg = config();
    if (!cfg || !cfg.input) return null;
    const label = document.querySelector(`label[for="${cfg.input}"], label[data-viser-for="${cfg.input}"]`);
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
    const canvas = viewCanvas();
    const message = JSON.stringify({
      kind: "pointer", n: state.seq, log_zoom: state.logZoom, x: state.x, y: state.y,
      nudge: [state.nudgeX, state.nudgeY],
      canvas: canvas ? [canvas.clientWidth, canvas.clientHeight] : null,
    });
    Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set.call(input, message);
    input.dispatchEvent(new Event("input", { bubbles: true }));
  };

  // a canvas of the viewer (there can be two of the same size, one over the other), not a small
  // one that draws text
  const canvasOf = (target) => {
    if (!target || target.tagName !== "CANVAS") return null;
    const view = viewCanvas();
    const area = (c) => c.clientWidth * c.clientHeight;
    return view && area(target) >= 0.5 * area(view) ? target : null;
  };
  const track = (event) => {
    const canvas = canvasOf(event.target);
    state.over = canvas !== null;
    if (!canvas) return;
    const box = canvas.getBoundingClientRect();
    state.x = (event.clientX - box.left) / box.width;
    state.y = (event.clientY - box.top) / box.height;
  };
  window.addEventListener("pointermove", track, { capture: true, passive: true });

  const ARROWS = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
  const zoomBy = (logFactor) => {
    state.logZoom += logFactor;
    send();
  };
  window.addEventListener(
    "wheel",
    (event) => {
      const cfg = config();
      if (!cfg || cfg.mode !== "image" || !canvasOf(event.target)) return;
      event.preventDefault();
      event.stopImmediatePropagation();
      track(event);
      const lines = event.deltaMode === 1 ? 16 : event.deltaMode === 2 ? 400 : 1;
      zoomBy(-0.0015 * event.deltaY * lines); // one notch (100 px) ~ x1.16
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
      if (!state.over) {
        state.x = 0.5;
        state.y = 0.5;
      }
      if (event.key === "+" || event.key === "=") zoomBy(Math.log(Math.SQRT2));
      else if (event.key === "-" || event.key === "_") zoomBy(-Math.log(Math.SQRT2));
      else return;
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
      label.setAttribute("data-viser-for", id); // what viser named it (the bridge finds its field so)
      if (!target) label.removeAttribute("for");
      else if (target.id) label.setAttribute("for", target.id); // it has an id of its own: point there
      else target.id = id;
    }
  };
  mendLabels();
  new MutationObserver(mendLabels).observe(document.body, { childList: true, subtree: true });
  // the canvas size in CSS pixels (the screen pixels a zoom is measured in; viser reports the
  // drawing buffer's, which shrinks when it lowers the resolution on a slow machine)
  const watchCanvas = () => {
    const canvas = viewCanvas();
    if (!canvas || !canvas.clientWidth || !field()) return setTimeout(watchCanvas, 200);
    new ResizeObserver(() => send()).observe(canvas);
  };
  watchCanvas();
})();
