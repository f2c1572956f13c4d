"""Nothing lost when two people edit at once (issue #32): two real browser tabs (two browser
contexts, both drawing) drag different points of one frame at the same moment, round after round;
every drag released is in the edits folder. And on a clip, edits keep coming while its shot is
solved again and cut: every one is saved, and the shot model holds them all."""

import shutil
import threading
import time

import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from test_app_browser import CHROMIUM, FLAGS, canvas_box, open_page, settle, tab, to_screen

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed "
                                "(scripts/install_test_deps.sh installs it)")
ROUNDS = 50


@pytest.fixture()
def data(tmp_path):
    dst = tmp_path / "set"
    (dst / "cameras").mkdir(parents=True)
    for stem in ("00000", "00001"):
        for name in (f"{stem}.jpg", f"{stem}.json", f"cameras/camera_{stem}.json"):
            shutil.copy(EXAMPLES_DIR / "sample" / name, dst / name)
    return dst


class _Contexts:
    """Opens pages in a browser context of their own (a tab in another window: it draws and
    takes the pointer while the other one does too)."""

    def __init__(self, context):
        self.context = context

    def new_page(self, **_):
        return self.context.new_page()


def _on_canvas(page, xy) -> bool:
    """The pointer at ``xy`` lands on the viewer, not on the panel or a notification over it."""
    return bool(page.evaluate("([x, y]) => { const e = document.elementFromPoint(x, y); "
                              "return !!e && e.tagName == 'CANVAS' }", list(xy)))


def _apart(session, key) -> bool:
    """No other point of the frame is drawn within 1.5 px of keypoint ``key`` (after rounds of
    drags two points can meet: a press there could mean either)."""
    mine = session.workspace.points["keypoints"]
    uv = mine.uv[mine.keys.index(key)]
    others = [p.uv[[i for i, k in enumerate(p.keys) if p is not mine or k != key]]
              for p in session.workspace.points.values() if p.keys]
    return all(np.hypot(*(o - uv).T).min(initial=np.inf) > 1.5 for o in others)


def test_two_tabs_dragging_at_the_same_moment_lose_nothing(data, tmp_path, serve):
    sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
    app = serve(data, edits=tmp_path / "edits")
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        contexts = [browser.new_context(viewport={"width": 1400, "height": 900}) for _ in range(2)]
        try:
            pages = [open_page(_Contexts(contexts[0]), app, "focal"), None]
            a = tab(app)
            pages[1] = open_page(_Contexts(contexts[1]), app, "focal", n=2)
            b = tab(app, 2)
            sessions = (a, b)
            assert a.stem == b.stem == "00000"
            moved: list[int] = []
            boxes = [canvas_box(page) for page in pages]  # the canvas stays where it is on the page
            for r in range(ROUNDS):
                for s in sessions:
                    settle(s, 0.1)
                starts, keys = [], []
                for page, s, box, offset in zip(pages, sessions, boxes, (0, 5)):
                    nodes = s.workspace.points["keypoints"]

                    def at(k, s=s, box=box, nodes=nodes):
                        x, y = to_screen(s, nodes.uv[nodes.keys.index(k)])
                        return np.array([box["x"] + x, box["y"] + y])

                    order = [nodes.keys[(r + offset + j) % len(nodes.keys)] for j in range(len(nodes.keys))]
                    k = next(k for k in order if k not in keys and _on_canvas(page, at(k)) and _apart(s, k))
                    keys.append(k)
                    starts.append(at(k))
                before = dict(app.state.edits.get("00000").get("keypoints") or {})
                steps = [np.array([0.0, 6.0 + r % 3]), np.array([6.0 + r % 2, 0.0])]
                for page, start in zip(pages, starts):  # both pointers down, then both move, then both up
                    page.mouse.move(*start)
                for page in pages:
                    page.mouse.down()
                for k in (1, 2):  # each step beyond viser's 3 px motion threshold
                    for page, start, step in zip(pages, starts, steps):
                        page.mouse.move(*(start + step * k / 2))
                for page in pages:
                    page.mouse.up()

                def changed(keys=keys, before=before):
                    now = app.state.edits.get("00000").get("keypoints") or {}
                    return [k for k in keys if now.get(str(k)) != before.get(str(k))]

                deadline = time.time() + 20
                while len(changed()) < 2:
                    assert time.time() < deadline, f"round {r}: drags of {keys} released, saved only {changed()}"
                    time.sleep(0.05)
                moved += keys
            assert a.editor.grabs == b.editor.grabs == ROUNDS
            saved = app.state.edits.get("00000")["keypoints"]
            assert {str(k) for k in moved} <= set(saved)
        finally:
            browser.close()


def test_edits_while_a_shot_is_solved_again_and_cut_are_all_kept(tmp_path):
    """On a 30-frame clip: while one thread places points on its frames (one per frame), another
    cuts the clip and removes the cut again; every edit is in the edits folder and in the shot
    model, which carries each one's pin."""
    import json
    from pnlviz.app.state import AppState
    from pnlviz.field import load_field_model
    from pnlviz.synth.annotate import annotate, annotation_to_json
    from pnlviz.synth.clip import clip_stem, plan_clip

    plan = plan_clip(21, 30, cuts=0)
    data = tmp_path / "clip"
    data.mkdir()
    for t, cam in enumerate(plan.cameras):  # annotations only: the frames calibrate at 960x540
        ann = annotation_to_json(annotate(cam, np.random.default_rng([21, t])))
        (data / f"{clip_stem(21, t)}.json").write_text(json.dumps(ann))
    st = AppState(data, edits=tmp_path / "edits")
    try:
        settings = st.default_settings
        shots = st.shots
        clip = next(iter(shots.clips))
        stems = shots.clips[clip]
        solver = shots.build(clip, settings)
        model = load_field_model()
        ids = np.array(model.keypoint_ids)
        placed: dict[str, tuple[int, np.ndarray]] = {}
        for t, stem in enumerate(stems):
            uv, z = plan.cameras[t].project_with_depth(model.keypoint_xyz(ids))
            ok = np.flatnonzero((z > 0) & plan.cameras[t].in_image(uv))
            j = ok[t % len(ok)]
            placed[stem] = (int(ids[j]), uv[j] + 1.0)
        errors: list[BaseException] = []

        def edit() -> None:
            try:
                for stem, (kid, uv) in placed.items():
                    st.move_keypoint(stem, kid, float(uv[0]), float(uv[1]), settings)
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)

        def cut() -> None:
            try:
                for _ in range(3):
                    shots.toggle_cut(stems[15], settings)
                    shots.toggle_cut(stems[15], settings)
            except BaseException as exc:  # noqa: BLE001
                errors.append(exc)

        threads = [threading.Thread(target=edit), threading.Thread(target=cut)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        assert errors == []
        solver = shots.build(clip, settings)
        for t, (stem, (kid, uv)) in enumerate(placed.items()):
            assert st.edits.get(stem)["keypoints"][str(kid)] == pytest.approx(list(uv))
            assert solver.edits.get(t, {}).get(str(kid)) == pytest.approx(list(uv)), stem
    finally:
        st.close()
