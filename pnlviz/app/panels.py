"""The panel of one tab (docked to the right of the image, narrow and collapsible): the widgets,
the keys, and which action of the tab's parts each one calls. Every callback goes through the
tab's queue (:meth:`pnlviz.app.tabqueue.TabQueue.ordered`), so actions run one at a time in the
order the browser sent them, and every value is checked by the action it reaches.
"""

from __future__ import annotations

import cv2
import numpy as np

from pnlviz.app.bridge import BRIDGE_FIELD, bridge_html
from pnlviz.app.modes import DragMode, Filter, Mode, Sort, labels
from pnlviz.app.overlay import LEGEND, SET_RGB
from pnlviz.viz import keypoint_map

LAYERS = ("keypoints", "ids", "ghosts", "refined_pitch", "initial_pitch", "reference_pitch", "annotation",
          "residuals", "detected_lines", "findings")
REVIEW_KEYS = {"accepted": "G", "corrected": "C", "rejected": "R"}
PANEL_WIDTH = 320
MAP_PX_PER_M = 6.0  # the keypoint map beside the picker (about 700 px wide before it is cropped)
MAP_CROP = 0.6  # the share of the map's width shown, around the chosen keypoint
MAP_TEXT_SCALE = 0.55  # the ids' font scale on it

#: every key of the app: (keys, what), for the help section (the bridge handles + and -, the
#: arrows, and viser's camera keys W A S D Q E, which pan and zoom the image view in the page)
KEYS = (
    ("wheel, + / -", "zoom around the pointer"),
    ("drag the image, right-drag", "pan"),
    ("W / S, A / D / Q / E", "zoom in / out; pan left / right / down / up"),
    ("0 / 1", "fit the frame / native resolution (1 image pixel = 1 screen pixel)"),
    ("V", "image view <-> 3D view (the pitch, the camera frustum)"),
    ("N / P", "next / previous frame (of the filter)"),
    ("G / C / R", "review: accepted / corrected / rejected, then the next frame"),
    ("H", "hide the points the outlier gate flagged on the frame reviewed last"),
    ("click a point", "select it (a ghost: choose its id)"),
    ("drag a point", "move it (a ghost: place it); the frame recalibrates as you drag"),
    ("shift+click", "place the chosen id there"),
    ("arrows (shift: x10)", "nudge the selected point by one image pixel"),
    ("Delete / Backspace", "mark the selected keypoint not visible"),
    ("Escape", "clear the selection"),
    ("Ctrl+Z / Ctrl+Shift+Z", "undo / redo (saved with the edits)"),
    ("Space", "play / pause the clip (video datasets: the Clip panel, its error strip, worst frames)"),
    ("Ctrl+K", "all commands"),
)


def keypoint_choices(model) -> tuple[str, ...]:
    """The picker's options, "45 · penalty mark left": searchable by id and by name."""
    return tuple(f"{k} · {name}" for k, name in sorted(model.keypoint_names().items()))


def choice_id(choice) -> int | None:
    """The id of a picker option ("45 · ..." or "45"), None for anything else."""
    head = str(choice).split(" ", 1)[0]
    return int(head) if head.isdigit() else None


def picker_map(model, kid: int | None) -> np.ndarray:
    """The keypoint map with ``kid`` highlighted, RGB, for the panel: the part of the pitch around
    it (:data:`MAP_CROP` of its length), so that the ids stay legible at the panel's width (about
    8 px tall on a 1600x900 screen; the whole pitch would make them 5)."""
    image = keypoint_map(model, px_per_m=MAP_PX_PER_M, highlight=kid, legend=False, text_scale=MAP_TEXT_SCALE)
    W = image.shape[1]
    width = int(W * MAP_CROP)
    x = W // 2
    if kid is not None and int(kid) in model.keypoints:
        x = int(round(W / 2 + MAP_PX_PER_M * float(model.keypoints[int(kid)].xyz[0])))
    left = int(np.clip(x - width // 2, 0, W - width))
    return cv2.cvtColor(np.ascontiguousarray(image[:, left:left + width]), cv2.COLOR_BGR2RGB)


def layer_words(name: str) -> str:
    """A layer's name as its checkbox shows it (and the legend names it)."""
    return name.replace("_", " ")


def legend_markdown() -> str:
    """The colour of every layer, under the name of its checkbox, and of the keypoint sets."""
    def swatch(rgb) -> str:
        return f'<span style="color:rgb{tuple(int(c) for c in rgb)}">&#9632;</span>'

    rows = [f"{swatch(c)} **{layer_words(name)}**: {text}" for name, (c, text) in LEGEND.items()]
    rows.append("**keypoints** by set: " + ", ".join(f"{swatch(c)} {name}" for name, c in SET_RGB.items()))
    return "<br>".join(rows)


def keys_markdown() -> str:
    """The keys an annotator uses most, in one line at the top of the panel."""
    return ("**G** accept · **C** corrected · **R** reject · **N/P** next/previous · **shift+click** place · "
            "**ctrl+click/drag** select more · **arrows** nudge · **Del** hide · **O** occluded · **Ctrl+Z** undo · "
            "**V** 3D · more: Help")


def busy_html(busy: bool) -> str:
    """The element the page script reads for the busy cue (bridge.js draws it over the image)."""
    return f'<div id="pnlviz-busy" data-busy="{int(bool(busy))}"></div>'


def help_markdown() -> str:
    return "\n".join(f"- **{keys}**: {what}" for keys, what in KEYS)


class Panels:
    """The widgets of one tab's panel (bound to the tab's parts by :func:`pnlviz.app.bindings.bind`):
    made in ``gui`` (the tab's viser GUI), with the tab's ``queue`` (values set in order),
    ``notify(title, body, error=True)``, the pitch ``model``, the dataset's ``clips`` and
    ``splits``, the painter's ``layers`` and the tab's first ``settings`` and keypoint ``sources``."""

    def __init__(self, gui, queue, notify, model, *, clips, splits, layers, settings, sources):
        self.queue, self.notify, self.model, self.splits = queue, notify, model, splits
        gui.configure_theme(control_width="medium", show_share_button=False)
        gui.main_panel.dock_right()
        gui.main_panel.set_width(PANEL_WIDTH)
        self.title = gui.add_markdown("")
        self.keys = gui.add_markdown(keys_markdown())
        self.status = gui.add_markdown("")
        self._frame_folder(gui)
        self._clip_folder(gui, clips)
        self._review_folder(gui)
        self._points_folder(gui)
        self._view_folder(gui, layers)
        self._calibration_folder(gui, settings, sources)
        with gui.add_folder("Help", expand_by_default=False):
            gui.add_markdown(help_markdown())
        self.background = gui.add_markdown("")
        # the pointer bridge: a text field it writes to (hidden by the bridge) and its loader
        self.bridge_field = gui.add_text(BRIDGE_FIELD, initial_value="")
        self.bridge = gui.add_html(bridge_html(BRIDGE_FIELD, Mode.IMAGE))
        #: the busy flag the page shows as a cue over the image (an action slower than 150 ms)
        self.busy = gui.add_html(busy_html(False))

    def _frame_folder(self, gui) -> None:
        with gui.add_folder("Frame"):
            self.slider = gui.add_slider("frame", min=1, max=2, step=1, initial_value=1)
            self.nav = gui.add_button_group("navigate", ("previous", "next"))
            self.jump = gui.add_text("jump to stem", initial_value="")
            self.filter = gui.add_dropdown("filter", labels(Filter), initial_value=Filter.ALL.value)
            splits = self.splits  # a dataset in split folders or zips
            self.split = gui.add_dropdown("split", ("all", *splits), initial_value="all") if splits else None
            self.sort = gui.add_dropdown("sort", labels(Sort), initial_value=Sort.INDEX.value)
            self.filter_text = gui.add_markdown("")

    def _clip_folder(self, gui, clips) -> None:
        """The clip timeline, for a video (a dataset without clips has none)."""
        self.clip_text = self.clip_strip = self.clip_slider = self.clip_buttons = None
        self.shot_box = self.shot_buttons = None
        if not clips:
            return
        from pnlviz.app.timeline import strip_image

        with gui.add_folder("Clip"):
            self.clip_text = gui.add_markdown("")
            self.clip_strip = gui.add_image(strip_image([], None), format="png")
            self.clip_slider = gui.add_slider("clip frame", min=1, max=2, step=1, initial_value=1)
            self.clip_buttons = gui.add_button_group("clip", ("play", "pause", "worst", "next worst"))
            self.shot_box = gui.add_checkbox("shot model", initial_value=True,
                                             hint="show the shot's camera (off: the frame's own camera, to compare)")
            self.shot_buttons = gui.add_button_group("shot", ("accept shot", "cut here"))

    def _review_folder(self, gui) -> None:
        with gui.add_folder("Review"):
            statuses = tuple(f"{k} ({v})" for k, v in REVIEW_KEYS.items()) + ("clear",)
            self.review = gui.add_button_group("status", statuses)
            self.advance = gui.add_checkbox("then next frame", initial_value=True)
            self.note = gui.add_text("note", initial_value="", hint="a note on this frame for a colleague: saved at once, "
                                                                    "exported in the manifest")
            self.gate_text = gui.add_markdown("")
            self.progress = gui.add_progress_bar(0.0)
            self.progress_text = gui.add_markdown("")

    def _points_folder(self, gui) -> None:
        model = self.model
        self.kp_choices = keypoint_choices(model)
        self._maps: dict[int, np.ndarray] = {}
        with gui.add_folder("Points"):
            self.selected = gui.add_markdown("")
            self.kp_id = gui.add_dropdown("place id", self.kp_choices, initial_value=self.kp_choices[0],
                                          hint="shift+click on the image places this keypoint; type an id or a "
                                               "name to find it")
            self.kp_map = gui.add_image(self.map_of(choice_id(self.kp_choices[0])), format="jpeg", jpeg_quality=85)
            self.points = gui.add_dropdown("on this frame", ("-",), initial_value="-",
                                           hint="the frame's keypoints: choose one to select it")
            self.hide = gui.add_button("not visible (Delete)")
            self.visibility = gui.add_button("visible / occluded / absent (O)")
            self.drag_mode = gui.add_dropdown("drag", labels(DragMode), initial_value=DragMode.KEYPOINTS.value)
            self.snap = gui.add_checkbox("snap to pitch", initial_value=False,
                                         hint="a point dropped within 8 screen pixels of a projected "
                                              "intersection or line goes onto it")
            self.history = gui.add_button_group("history", ("undo", "redo"))
            with gui.add_folder("Bulk", expand_by_default=False):
                self.bulk_action = gui.add_dropdown("do", ("absent", "occluded", "visible", "rename"),
                                                    initial_value="absent",
                                                    hint="to the selected keypoint (else the place id) on every frame "
                                                         "of the scope that shows it")
                self.bulk_scope = gui.add_dropdown("on", ("this frame", "this shot", "filtered frames"),
                                                   initial_value="filtered frames")
                self.bulk_to = gui.add_number("rename to", initial_value=1, min=1, max=73, step=1)
                self.bulk_apply = gui.add_button("apply (count first)")
                self.bulk_text = gui.add_markdown("")
            self.export = gui.add_button("export labels (zip)")

    def _view_folder(self, gui, layers) -> None:
        with gui.add_folder("View"):
            self.view_buttons = gui.add_button_group("view", ("fit (0)", "1:1 (1)", "3D (V)"))
            self.zoom_text = gui.add_markdown("")
            self.opacity = gui.add_slider("overlay opacity", min=0.1, max=1.0, step=0.05, initial_value=1.0)
            self.layer_boxes = {name: gui.add_checkbox(layer_words(name), initial_value=getattr(layers, name))
                                for name in LAYERS}
            self.legend = gui.add_markdown(legend_markdown())

    def _calibration_folder(self, gui, settings, sources) -> None:
        with gui.add_folder("Calibration"):
            self.card = gui.add_markdown("")
            self.top_view = gui.add_image(np.zeros((8, 8, 3), np.uint8), format="jpeg", jpeg_quality=85)
            self.pnl = gui.add_checkbox("PnL refinement", initial_value=settings.pnl)
            self.alpha = gui.add_slider("alpha (lines vs points)", min=0.0, max=1.0, step=0.05,
                                        initial_value=settings.alpha)
            self.sources = sources
            self.source = gui.add_dropdown("keypoint source", sources, initial_value=settings.source)

    def set_busy(self, busy: bool) -> None:
        """The tab is at work on an action (shown over the image by the page) or done."""
        self.busy.content = busy_html(busy)

    def set_mode(self, mode: Mode) -> None:
        self.bridge.content = bridge_html(BRIDGE_FIELD, mode)

    # ------------------------------------------------------------------ the picker
    def map_of(self, kid: int | None) -> np.ndarray:
        """The keypoint map with ``kid`` highlighted (each drawn once per tab)."""
        key = -1 if kid is None else int(kid)
        if key not in self._maps:
            self._maps[key] = picker_map(self.model, kid)
        return self._maps[key]

    def choice_of(self, kid: int) -> str:
        """The picker's option of keypoint ``kid`` ("45 · penalty mark left")."""
        return self.kp_choices[[choice_id(c) for c in self.kp_choices].index(kid)]

    def show_place_id(self, kid: int) -> None:
        """The picker and its map on ``kid``."""
        self.queue.set_value(self.kp_id, self.choice_of(kid))
        self.kp_map.image = self.map_of(kid)

    # ------------------------------------------------------------------ values from the browser
    def choice(self, handle, options, fallback: str) -> str:
        """The dropdown's value if it is one of ``options``; else it is reset to ``fallback``."""
        value = handle.value
        if value in options:
            return value
        self.notify("refused", f"{handle.label}: {str(value)[:40]!r} is not one of the options")
        self.queue.set_value(handle, fallback)
        return fallback

    def set_order(self, n: int, pos: int) -> None:
        """The slider over ``n`` frames at position ``pos`` (from 0); it counts from 1, as the title
        does (disabled when there is only one frame)."""
        self.slider.max = max(2, n)
        self.slider.disabled = n <= 1
        self.queue.set_value(self.slider, int(np.clip(pos, 0, max(0, n - 1))) + 1)
