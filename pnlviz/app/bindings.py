"""A tab's panel bound to its parts: each widget and each hotkey to the part that acts on it (the
session is the one place that knows every part; the parts and the panel do not know each other)."""

from __future__ import annotations

from collections.abc import Callable

from pnlviz.app.bridge import VIEW_KEYS


def bind(s) -> None:
    """Every widget of tab ``s``'s panel and every hotkey bound to the part that acts on it."""
    p, on = s.panels, s.queue.ordered
    edit, view, painter = s.editor, s.view_control, s.painter
    p.slider.on_update(on(lambda _: s.slider_moved(p.slider.value)))
    p.nav.on_click(on(lambda e: s.step(-1 if e.target.value == "previous" else 1)
                         if e.target.value in ("previous", "next") else None))
    p.jump.on_update(on(lambda _: s.jump(p.jump.value)))
    p.filter.on_update(on(lambda _: s.set_filter(p.filter.value)))
    p.sort.on_update(on(lambda _: s.set_sort(p.sort.value)))
    if p.split is not None:
        split = p.split
        split.on_update(on(lambda _: s.set_split(split.value)))
    p.review.on_click(on(lambda e: edit.review(str(e.target.value).split(" (")[0], advance=p.advance.value)))
    p.kp_id.on_update(on(lambda _: edit.set_place_id(p.kp_id.value)))
    p.points.on_update(on(lambda _: edit.select_listed(p.points.value)))
    p.hide.on_click(on(lambda _: edit.hide_selected()))
    p.visibility.on_click(on(lambda _: edit.cycle_visibility()))
    p.bulk_apply.on_click(on(lambda _: edit.bulk(p.bulk_action.value, p.bulk_scope.value,
                                                    int(p.bulk_to.value))))
    p.note.on_update(on(lambda _: edit.set_note(p.note.value)))
    p.drag_mode.on_update(on(lambda _: edit.set_drag_mode(p.drag_mode.value)))
    p.snap.on_update(on(lambda _: edit.set_snap(p.snap.value)))
    p.history.on_click(on(lambda e: edit.undo() if e.target.value == "undo" else edit.redo()))
    p.export.on_click(on(lambda _: s.export()))
    p.view_buttons.on_click(on(lambda e: {"fit (0)": view.fit, "1:1 (1)": view.native, "3D (V)": s.toggle_mode}
                                  .get(e.target.value, lambda: None)()))
    p.opacity.on_update(on(lambda _: painter.set_opacity(p.opacity.value)))
    for name, box in p.layer_boxes.items():
        box.on_update(on(lambda _, name=name, box=box: painter.set_layer(name, box.value)))
    p.pnl.on_update(on(lambda _: s.set_pnl(p.pnl.value)))
    p.alpha.on_update(on(lambda _: s.set_alpha(p.alpha.value)))
    p.source.on_update(on(lambda _: s.set_source(p.source.value)))
    p.bridge_field.on_update(on(lambda _: view.bridge_message(p.bridge_field.value)))
    if p.clip_slider is not None and p.clip_buttons is not None:  # made together
        clip = s.clip
        p.clip_slider.on_update(on(lambda _: clip.slider_moved(p.clip_slider.value)))
        actions = {"play": clip.play, "pause": clip.pause, "worst": lambda: clip.jump_worst(restart=True),
                   "next worst": clip.jump_worst}
        p.clip_buttons.on_click(on(lambda e: actions.get(e.target.value, lambda: None)()))
        box, buttons = p.shot_box, p.shot_buttons
        if box is not None and buttons is not None:  # made with the clip slider
            box.on_update(on(lambda _: clip.set_shot_model(box.value)))
            shot_actions = {"accept shot": clip.accept_shot, "cut here": clip.toggle_cut}
            buttons.on_click(on(lambda e: shot_actions.get(e.target.value, lambda: None)()))
    _bind_keys(s)


def _bind_keys(s) -> None:
    p, gui = s.panels, s.gui
    edit, view = s.editor, s.view_control
    keys: tuple[tuple[str, str, str | None, Callable[[], object]], ...]
    keys = (("next frame", "N", None, lambda: s.step(1)),
            ("previous frame", "P", None, lambda: s.step(-1)),
            ("review: accepted, next", "G", None, lambda: edit.review("accepted", advance=p.advance.value)),
            ("review: corrected, next", "C", None, lambda: edit.review("corrected", advance=p.advance.value)),
            ("review: rejected, next", "R", None, lambda: edit.review("rejected", advance=p.advance.value)),
            ("hide the flagged points of the frame reviewed last", "H", None, edit.hide_flagged),
            ("apply the label-error finder's fix (suspects)", "F", None, edit.apply_fix),
            ("undo", "Z", "cmd/ctrl", edit.undo),
            ("redo", "Z", "cmd/ctrl+shift", edit.redo),
            ("image view / 3D view", "V", None, s.toggle_mode),
            ("fit the frame", VIEW_KEYS[0], None, view.fit),
            ("native resolution", VIEW_KEYS[1], None, view.native),
            ("selected point: visible, occluded, absent", "O", None, edit.cycle_visibility),
            ("selected point not visible", "delete", None, edit.hide_selected),
            ("selected point not visible ", "backspace", None, edit.hide_selected),
            ("clear the selection", "escape", None, lambda: edit.select(None)))
    if s.clip.clips:
        keys += (("play / pause the clip", "space", None, s.clip.toggle),)
    for label, key, modifier, action in keys:
        prefix = modifier.replace("cmd/ctrl", "Ctrl").replace("+shift", "+Shift") + "+" if modifier else ""
        description = prefix + key
        command = gui.add_command(label, hotkey=key, modifier=modifier, description=description)
        command.on_trigger(s.queue.ordered(lambda _, action=action: action()))


__all__ = ["bind"]
