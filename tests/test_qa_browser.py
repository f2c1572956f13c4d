"""The label-error finder in the app, with real events: the suspects filter goes to the frame
it flags, the finding is drawn on it and listed, F applies the suggested fix as an edit, Ctrl+Z
takes it back."""

import json

from test_app_browser import browser, chromium, data, open_page, tab, wait_for_text, wait_until  # noqa: F401


def test_suspects_filter_then_f_fixes_the_frame_and_ctrl_z_undoes_it(data, browser, serve):  # noqa: F811
    path = data / "00000.json"
    ann = json.loads(path.read_text())
    ann["Circle left"] = ann.pop("Circle right")  # the penalty arc named from the other side
    path.write_text(json.dumps(ann))
    app = serve(data)
    app._worker.join(timeout=240)  # the background pass over every frame has ended (slow under load)
    assert not app._worker.is_alive(), "the background pass did not end within 240 s"
    st = app.state
    assert st.triage.lookup("00000").suspect >= 1 and st.triage.lookup("00002").suspect < 1
    page = open_page(browser, app, "focal")
    session = tab(app)
    session.queue.enqueue(lambda: session.goto(st.find("00002")))
    wait_until(lambda: session.stem == "00002")
    page.get_by_label("filter").click()
    page.get_by_role("option", name="suspects", exact=True).click()
    wait_until(lambda: session.stem == "00000")

    def classes():
        return set(st.view("00000").annotation)

    def drawn(layer):
        overlay = session.painter.overlay
        return overlay is not None and len(overlay.segments.get(layer, ())) > 0

    # the finding on the frame: the arc where the annotation put it, where the camera expects it
    wait_until(lambda: drawn("finding_annotated") and drawn("finding_expected"))
    wait_for_text(page, "label errors")
    wait_for_text(page, "'Circle left' fits the pitch as 'Circle right'")
    page.mouse.move(700, 450)
    page.keyboard.press("f")
    wait_until(lambda: "Circle right" in classes() and "Circle left" not in classes(), timeout=30)
    wait_for_text(page, "fix applied")
    wait_until(lambda: not drawn("finding_annotated"))  # fixed: nothing left to draw
    page.keyboard.press("Control+z")
    wait_until(lambda: "Circle left" in classes(), timeout=30)
    page.close()


def test_a_frame_not_judged_yet_is_drawn_at_once_and_its_findings_follow(data, serve):  # noqa: F811
    """Drawing a frame the label-error finder has not judged does not wait for it: the frame is
    drawn without findings, judged right after on the tab's queue, and its findings then appear on
    the image and in the panel's card."""
    from pnlviz.app import triage

    path = data / "00000.json"
    ann = json.loads(path.read_text())
    ann["Circle left"] = ann.pop("Circle right")
    path.write_text(json.dumps(ann))
    app = serve(data)
    session = app.session()
    session.flush()
    view = app.state.view("00000")
    with triage._JUDGED_LOCK:
        triage._JUDGED.clear()  # not judged yet (the background pass may judge it again meanwhile)
    if triage.judge_view(view, judge=False) is triage.NOT_JUDGED:
        session.painter._judged = None
        assert session.painter.findings(view) == []  # drawn without: the verdict is queued
    session.queue.enqueue(lambda: session.goto(app.state.find("00000")))
    session.flush()
    session.flush()  # the verdict queued by the draw, and its redraw

    def drawn(layer):
        overlay = session.painter.overlay
        return overlay is not None and len(overlay.segments.get(layer, ())) > 0

    wait_until(lambda: drawn("finding_annotated") and "label errors" in session.panels.card.content)
    assert "'Circle left' fits the pitch as 'Circle right'" in session.panels.card.content
