"""What a tab's editor says and asks about a frame while it is edited: a hand point that looks like
a slip (said in the panel at once), and an accept the label-error finder disagrees with (asked
once). Functions of the editor's tab, kept apart from the editing itself."""

from __future__ import annotations

from pnlviz.app.state import EditError


def distance_text(px: float) -> str:
    """A point's distance from where the camera puts it, in words ("44 px", "off camera")."""
    return "off camera" if px == float("inf") else f"{px:.0f} px"


def distances_text(found: dict[int, float]) -> str:
    """``{id: px}`` as "12 (44 px), 19 (off camera)"."""
    return ", ".join(f"{k} ({distance_text(r)})" for k, r in sorted(found.items()))


def say_slip(tab, stem: str, kid: int) -> None:
    """After a keypoint was placed or moved by hand: when the rest of the frame puts it farther
    than the outlier gate from where it was put (:func:`pnlviz.pipeline.snapshot.hand_slips`),
    say so at once; the point stays where the hand put it. A reviewed frame's snapshot, taken
    with the edit, has judged them already: read there, not judged twice."""
    from pnlviz.pipeline.snapshot import hand_slips, recorded_slips

    state, settings = tab.state, tab.settings
    try:
        found = recorded_slips(state.edits.get(stem), settings)
        if found is None:
            view = state.view(stem, settings)
            found = hand_slips(view, state.reader.frame_settings(view.settings), state.model, kids=[kid])
    except EditError:
        return
    if kid not in found:
        if "a slip?" in tab.panels.gate_text.content:  # put right: the notice goes
            tab.panels.gate_text.content = ""
        return
    text = (f"**point {kid} is {distance_text(found[kid])} from where the rest of {stem} puts it: a slip?** It stays where "
            f"you put it (a hand's point is never moved) and is listed as a possible slip when the frame "
            f"is reviewed and in the export's manifest; Ctrl+Z takes it back.")
    tab.panels.gate_text.content = text  # in the panel, not a notice over the image the hand works on


def ask_before_accepting(editor, stem: str) -> bool:
    """Accepting a frame the label-error finder flags (a class on the wrong side, a mirrored
    frame: :func:`pnlviz.app.triage.judge_view`) asks once: True (not accepted) the first time,
    with the finding said; the same frame with the same edits accepted at the second G."""
    from pnlviz.app.triage import judge_view

    state = editor.tab.state
    qa = judge_view(state.view(stem, editor.tab.settings))
    if qa is None or qa.score < 1 or not qa.findings:
        return False
    key = (stem, state.edits.digest(stem))
    if editor.asked == key:
        editor.asked = None
        return False
    editor.asked = key
    worst = qa.findings[0]
    fix = " **F** applies its suggested fix;" if worst.fix is not None else ""
    text = (f"**{stem} not accepted yet: the label-error finder flags it** ({worst.message}).{fix} "
            f"**G** again accepts it as it is.")
    editor.tab.notify(f"{stem}: accept anyway?", text.replace("**", ""), error=False)
    editor.tab.panels.gate_text.content = text
    return True


def say_flagged(editor, stem: str) -> None:
    """After a review: the points of the frame the export's outlier gate flags, said in the
    panel and remembered for H (:meth:`pnlviz.app.editing.Editor.hide_flagged`)."""
    from pnlviz.pipeline.snapshot import REVIEWED, snapshot_flags

    record = editor.tab.state.edits.get(stem)
    reviewed = record.get("review") in REVIEWED
    flagged, limit = snapshot_flags(record) if reviewed else ({}, 0.0)
    slips = {int(k): float("inf") if v is None else float(v)
             for k, v in ((record.get("snapshot") or {}).get("slips") or {}).items()} if reviewed else {}
    editor.flagged = (stem, sorted(flagged)) if flagged else None
    text = ""
    if flagged:
        ids = distances_text(flagged)
        text = (f"**{stem}: {len(flagged)} point{'s' if len(flagged) > 1 else ''} flagged** (farther than "
                f"{limit:.1f} px from the camera; exported flagged, not as ground truth): {ids}. "
                f"**H** hides them.")
        editor.tab.notify(f"{len(flagged)} flagged on {stem}", text.replace("**", ""), error=False)
    if slips:
        ids = distances_text(slips)
        more = (f"**{stem}: {len(slips)} point{'s' if len(slips) > 1 else ''} placed by hand far from where the "
                f"rest of the frame puts {'them' if len(slips) > 1 else 'it'}** (possible slips, kept as placed "
                f"and listed in the export's manifest): {ids}.")
        editor.tab.notify(f"{len(slips)} possible slip{'s' if len(slips) > 1 else ''} on {stem}",
                        more.replace("**", ""), error=False)
        text = f"{text} {more}".strip()
    editor.tab.panels.gate_text.content = text
