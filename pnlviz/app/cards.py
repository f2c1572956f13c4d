"""The texts of a tab's panel, as pure functions of what they show (markdown, or the rows of a
dropdown): the calibration card and the label-error findings under it, the title and status
lines, the points list, the selected point, the review progress, the clip line, the zoom.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np

from pnlviz.app.modes import PointKind, Selection
from pnlviz.app.overlay import Overlay
from pnlviz.app.shots import SHOT_SUBSET
from pnlviz.app.state import AppState, FrameView
from pnlviz.calib.line_start import LINE_SUBSET
from pnlviz.calib.looks import second_look_count


#: the starts of a frame whose keypoints are too few for a homography (its result's ``subset``), in words
STARTS = {"prior": "a broadcast camera's usual place", LINE_SUBSET: "its straight lines"}


def calibration_card(view: FrameView, state: AppState) -> str:
    """Markdown of the calibration card."""
    lines = []
    if view.error:
        lines.append(f"**error**: {view.error}")
    elif view.stem in state.image_errors:
        lines.append(f"**image not shown**: {state.image_errors[view.stem]}")
    res = view.result
    if view.origin is not None:
        settings = state.applied_detection_settings(view.origin, view.settings)
        used = ", ".join(f"{k}={v}" for k, v in settings.items())
        lines.append(f"calibrated from: **{view.origin}**"
                     + (f" (the detector's settings: {used})" if settings else ""))
        looked = second_look_line(state.reader.detections(view.stem), settings)
        if looked is not None and (view.result is None or view.result.subset != SHOT_SUBSET):
            lines.append(looked)  # (a shot's camera says why it carries the frame)
    if view.reference_camera is not None:
        lines.append("reference camera (magenta): known for this frame")
    if res is None:
        return "\n\n".join(lines or ["nothing to calibrate from yet: place four keypoints (shift+click)"])
    cam = res.camera
    if cam is None:  # not res.ok
        lines.append(f"**not calibrated**: {res.failure}")
        return "\n\n".join(lines)
    pan, tilt, roll = cam.pan_tilt_roll_deg
    errs = np.array([v for v in res.point_residuals.values() if np.isfinite(v)])
    line_errs = np.array(list(res.line_residuals.values()))
    lines += [
        f"focal **{cam.fx:.1f} px** (hFOV {cam.hfov_deg:.1f} deg), k1 {cam.radial[0]:+.3f}",
        (f"position ({cam.C[0]:.1f}, {cam.C[1]:.1f}, {cam.C[2]:.1f}) m; "
         f"pan {pan:.2f}, tilt {tilt:.2f}, roll {roll:.2f} deg"),
        f"keypoints: {len(errs)}, median error {np.median(errs):.2f} px" if len(errs) else "keypoints: none",
        f"lines/circles: {len(line_errs)}, worst {line_errs.max():.1f} px" if len(line_errs) else "lines: none",
    ]
    if res.subset == SHOT_SUBSET:
        lines.append("the **shot model**'s camera (one centre and lens for the shot, solved with every hand edit "
                     "of it; the frame's own camera: the Clip panel's toggle)")
    if view.shot_note:
        lines.append(view.shot_note)
    if res.subset in STARTS:
        lines.append(f"too few keypoints for a homography: started from **{STARTS[res.subset]}**, "
                     f"{len(res.inliers)} inliers; PnL set: {len(res.pnl_lines)} lines/circles"
                     + _left_out(res.lines_alone, state.model.unmarked_points()))
    elif res.subset != SHOT_SUBSET:
        lines.append(f"won: subset **{res.subset}**, RANSAC {res.threshold:g} px, {res.plane} plane, "
                     f"{len(res.inliers)} inliers; PnL set: {len(res.pnl_lines)} lines/circles"
                     + _left_out(res.lines_alone, state.model.unmarked_points()))
    if res.half is not None:
        lines.append(f"its points name **both ends** of the pitch and gave no camera together: this one is from "
                     f"the **{res.half} half**'s points alone; the others may carry the wrong end's ids")
    lines += pin_lines(res)
    if view.jac:
        lines.append("JaC vs annotation: " + ", ".join(f"@{t} **{v:.2f}**" for t, v in view.jac.items()))
    lines.append(f"computed in {view.ms:.0f} ms")
    return "\n\n".join(lines)


def second_look_line(pred, settings: Mapping) -> str | None:
    """The card's word on detections read a second time (their first reading gave no camera):
    how many score under the detector's thresholds (``shot_min_score``); None when none do."""
    weak = second_look_count(pred, settings)
    if not weak:
        return None
    floor = settings["shot_min_score"]
    return (f"**a second look**: {weak} of its detections score under the detector's thresholds "
            f"({floor[0]:g} keypoints, {floor[1]:g} lines); read because the others gave no camera, "
            "they often fit a wrong one: check it against the picture")


def _left_out(ids: Sequence[int], unmarked: Mapping[int, str]) -> str:
    """The PnL set's note on the keypoints its lines and circles fix without: those derived from
    them, and those no paint marks (held to their marking only)."""
    derived = [k for k in ids if k not in unmarked]
    on = [k for k in ids if k in unmarked]
    parts = ([f"the {len(derived)} keypoint{'s' * (len(derived) != 1)} derived from them"] if derived else []) + (
        [f"{len(on)} that no paint marks ({', '.join(map(str, on))}: held to their marking only)"] if on else [])
    return f", fitted without {' and '.join(parts)}" if parts else ""


def findings_text(marks) -> str:
    """Markdown of a frame's label-error findings (:func:`pnlviz.calib.qa.finding_marks`), the
    first fix's key; empty without findings."""
    if not marks:
        return ""
    rows = [f"- **{m.finding.kind.replace('_', ' ')}**: {m.finding.message}" for m in marks]
    has_fix = any(m.finding.fix is not None for m in marks)
    return ("\n\n**label errors** (pink: as annotated, green: where the camera expects it"
            + ("; **F** applies the first fix" if has_fix else "") + ")\n\n" + "\n".join(rows))


def pin_lines(res) -> list[str]:
    """The card's lines on the pinned keypoints: how many, and each one the camera cannot agree
    with, by how far (flagged, not dropped)."""
    if not res.pinned:
        return []
    lines = [f"pinned (placed by hand): {len(res.pinned)} point" + ("s" if len(res.pinned) != 1 else "")
             + f" ({', '.join(str(k) for k in sorted(res.pinned))})"]
    lines += [f"**pinned point {k} is {r:.0f} px from the camera**" for k, r in sorted(res.flagged.items())]
    return lines


def keypoint_name(model, kid: int) -> str:
    """What a keypoint is, in words, distinct for every id (:meth:`FieldModel.keypoint_names`),
    with its set."""
    kp = model.keypoints.get(int(kid))
    if kp is None:
        return "?"
    return f"{model.keypoint_names()[int(kid)]} ({kp.group})"


def title_text(view: FrameView, position: int, n: int, outside: bool, flt: str, key: str | None = None) -> str:
    """The frame's stem, where it is in the filter (``position`` from 1 of ``n``), its size, and
    what the tab's sort sees of it (``key``)."""
    where = (f"not in the filter '{flt}' (no frame is)" if outside
             else f"{position}/{n}" + (f" of '{flt}'" if flt != "all" else ""))
    return f"### {view.stem}\n{where} · {view.size[0]}x{view.size[1]}" + (f"  \nsorted by **{key}**" if key else "")


def filter_text(stem: str, n: int, outside: bool, flt: str) -> str:
    """How many frames the filter lets through (or that none does)."""
    if outside:
        return f"**no frame matches '{flt}'**: showing {stem}"
    return f"{n} frame" + ("s" if n != 1 else "")


def status_line(view: FrameView, review: str | None, record: Mapping, save_error: str | None,
                detection: str | None) -> str:
    """The frame's review status, whether its edits are saved, what the detector does there,
    and why it has no camera (where it is seen first; the card says more)."""
    if save_error:
        saved = f"**not saved**: {save_error}"
    elif record.get("updated"):
        saved = "saved " + time.strftime("%H:%M:%S", time.localtime(record["updated"]))
    else:
        saved = "no edits"
    line = f"review: **{review or 'not reviewed'}** · {saved}" + (f" · {detection}" if detection else "")
    if view.error:
        line += f"  \n**problem**: {view.error}"
    elif view.result is not None and not view.result.ok:
        line += f"  \n**not calibrated**: {view.result.failure}"
    return line


def point_rows(overlay: Overlay | None, hidden: set[int]) -> list[str]:
    """The rows of the points list: "-", then every keypoint visible (with its residual), hidden
    and ghost."""
    rows = ["-"]
    if overlay is not None:
        labels = dict(zip(overlay.keypoints.keys, overlay.keypoints.labels))
        for kid in sorted(overlay.keypoints.keys):
            r = overlay.residuals.get(kid)
            pin = " · flagged pin" if kid in overlay.flagged else " · pinned" if kid in overlay.pinned else ""
            seen = "occluded" if str(labels.get(kid, "")).startswith("(") else "visible"  # "(12)": occluded
            rows.append(f"{kid} · {seen}{pin}" + (f" · {r:.1f} px" if r is not None else ""))
        rows += [f"{kid} · hidden" for kid in sorted(hidden)]
        rows += [f"{kid} · ghost" for kid in sorted(overlay.ghosts.keys)]
    return rows


def listed_id(row) -> int | None:
    """The keypoint id a row of the points list names ("12 · visible · 0.8 px": 12), else None."""
    text = str(row).split(" ")[0]
    return int(text) if text.isdigit() else None


def selected_text(selected: Selection | None, overlay: Overlay | None, model, place_id: int,
                  also: Sequence[int] = ()) -> str:
    """What is selected: its id and name (or line and index), residual, and where it is; with
    ``also`` (more selected keypoints: Ctrl+click, a Ctrl+drag box) how many and which."""
    if selected is not None and also:
        ids = ", ".join(str(k) for k in [selected.key, *also])
        return f"**{1 + len(also)} keypoints selected** ({ids}) · **Del** hides them · **O** occluded · one undo step"
    if selected is None or overlay is None:
        return f"nothing selected · shift+click places **{place_id}** {keypoint_name(model, place_id)}"
    key = selected.key
    if selected.kind is PointKind.LINE_POINTS:
        m = overlay.line_points
        name, index = selected.line_point
        text = f"**{name}**, point {index}"
    else:
        m = overlay.keypoints if selected.kind is PointKind.KEYPOINTS else overlay.ghosts
        text = f"**{key}** {keypoint_name(model, selected.kid)}"
        if selected.kind is PointKind.GHOSTS:
            text += " · not observed: drag it where it is"
        elif key in overlay.residuals:
            text += f" · residual {overlay.residuals[key]:.2f} px"
        if key in overlay.flagged:
            text += " · pinned, the camera cannot agree with it"
        elif selected.kind is PointKind.KEYPOINTS and key in overlay.pinned:
            text += " · pinned"
    if key in m.keys:
        u, v = m.uv[m.keys.index(key)]
        text += f" · at ({u:.1f}, {v:.1f})"
    return text


def progress_text(done: int, total: int, counts: Mapping[str, int]) -> str:
    return f"{done} of {total} reviewed: " + ", ".join(f"{k} {v}" for k, v in counts.items())


def clip_text(name: str, position: int, errors: list[float], playing: bool) -> str:
    """The clip line: the frame's place in its clip (``position`` from 0), its error, how many
    frames of the clip are calibrated yet, and whether it plays."""
    e, n = errors[position], len(errors)
    said = "not calibrated yet" if np.isnan(e) else "no camera" if np.isinf(e) else f"error {e:.1f} px"
    done = sum(not np.isnan(v) for v in errors)
    return (f"**{name}**: frame {position + 1} of {n} · {said}" + ("" if done == n else f" · {done} calibrated")
            + (" · playing" if playing else ""))


def zoom_text(zoom: float) -> str:
    return f"zoom **{zoom:.2f}x** (screen pixels per image pixel)"


__all__ = ["calibration_card", "clip_text", "filter_text", "keypoint_name", "listed_id", "point_rows",
           "progress_text", "selected_text", "status_line", "title_text", "zoom_text"]
