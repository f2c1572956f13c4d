"""Screenshots of the app for the README and docs/app.md, taken in headless Chromium (Debian's `chromium`).

    python scripts/screenshots.py        # writes docs/screenshots/*.jpg

Edits go to a temporary folder: the bundled sample is not touched.
"""

from __future__ import annotations

import json
import shutil
import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
from playwright.sync_api import sync_playwright

from pnlviz import EXAMPLES_DIR, REPO_ROOT
from pnlviz.app.modes import Mode
from pnlviz.app.server import PnlvizApp
from pnlviz.app.state import AppState
from pnlviz.app.view2d import View2D
from pnlviz.detect.worker import DetectorProcess

OUT = REPO_ROOT / "docs" / "screenshots"
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def shoot(page, name: str) -> None:
    for close in page.locator(".mantine-Notification-closeButton").all():  # the software-WebGL notice
        close.click()
    time.sleep(2.5)
    png = OUT / f"{name}.png"
    page.screenshot(path=str(png))
    img = cv2.imread(str(png))
    cv2.imwrite(str(OUT / f"{name}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 82])
    png.unlink()
    print(f"wrote {OUT / name}.jpg")


def session(browser, data: Path, edits: Path, shots: list[tuple[str, str, Callable | None]],
            detect: bool = False) -> None:
    """Open ``data`` in a page and take each shot: (file name, frame, what to do on it first);
    ``detect``: with the light default model in the background, as ``pnlviz serve`` runs it."""
    detector = DetectorProcess(threads=1) if detect else None
    state = AppState(data, edits=edits, detector=detector, source="annotation" if detect else None)
    app = PnlvizApp(state, port=free_port())
    if detector is not None:
        detector.warm_up()
    try:
        page = browser.new_page(viewport={"width": 1600, "height": 900})
        page.goto(app.url)
        page.get_by_text("Calibration").first.wait_for(timeout=30000)
        tab = app.tabs()[0]
        deadline = time.time() + 30
        while tab.view_control.css_canvas is None and time.time() < deadline:  # the page bridge has reported the canvas
            time.sleep(0.2)
        for name, stem, before in shots:
            tab.queue.enqueue(lambda stem=stem: tab.goto(app.state.find(stem)))
            tab.flush()
            time.sleep(1.0)
            if before is not None:
                before(page, tab)
                tab.flush()
            shoot(page, name)
            tab.queue.enqueue(lambda: tab.set_mode(Mode.IMAGE))
            tab.queue.enqueue(lambda: tab.editor.select(None))
            tab.queue.enqueue(tab.view_control.fit)
            tab.flush()
        page.close()
    finally:
        app.stop()
        app.state.close()


def select_leftmost(page, tab) -> None:
    """Click the leftmost keypoint (it shows selected, with its id, set and residual); a frame
    with an image only waits for the light model's detections first."""
    nodes = tab.workspace.points["keypoints"]
    deadline = time.time() + 60
    while not nodes.keys and time.time() < deadline:
        time.sleep(0.5)
    tab.flush()
    time.sleep(1.0)
    i = int(nodes.uv[:, 0].argmin())
    box = max((c.bounding_box() for c in page.locator("canvas[data-engine]").all()),
              key=lambda b: b["width"] * b["height"])  # the viewer's (three.js marks it)
    x, y = tab.view_control.view2d.to_screen(nodes.uv[i], tab.view_control.canvas)
    page.mouse.click(box["x"] + x, box["y"] + y)


def zoom_on_densest(page, tab) -> None:
    """Zoom 4x (screen pixels per image pixel) around the densest group of keypoints."""
    nodes = tab.workspace.points["keypoints"]
    uv = nodes.uv
    crowd = int(((uv[:, None] - uv[None]) ** 2).sum(-1).__lt__(60.0 ** 2).sum(1).argmax())
    tab.queue.enqueue(lambda: tab.view_control.push(View2D(*uv[crowd], 4.0)))


def three_d(page, tab) -> None:
    page.mouse.click(5, 450)  # the page has the keys
    page.keyboard.press("v")


def clip_calibrated(page, tab) -> None:
    """Every frame of the clip calibrated (the background worker would get there), the panel redrawn."""
    for i in tab.clip.members():
        tab.state.view(tab.state.stems[i], tab.settings)
    tab.queue.enqueue(tab.show)


def shot_model(page, tab) -> None:
    """The clip under its shot model: every frame calibrated, the shots solved, a point moved by
    hand on a frame before this one (a keyframe on the strip), the panel redrawn."""

    clip_calibrated(page, tab)
    st = tab.state
    shots = st.shots
    place = shots.place(tab.stem, tab.settings, build=False)
    shots.build(place.clip, tab.settings)
    other = place.stems[max(0, place.t - 6)]  # a keyframe six frames before this one
    obs = st.view(other, tab.settings).observations
    st.move_keypoint(other, int(obs.kp_ids[0]), float(obs.kp_xy[0, 0]) + 1.0, float(obs.kp_xy[0, 1]), tab.settings)
    tab.queue.enqueue(tab.show)


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=("sample", "failed", "clip", "shots"), default=None, help="one session only")
    only = ap.parse_args().only
    OUT.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp())
    from pnlviz.synth import generate

    generate(tmp / "clip", 40, 11, clip=True, progress=False)  # a synthetic video clip with a cut
    # a frame whose annotation holds two lines only: too little to calibrate
    failed = tmp / "failed"
    (failed / "cameras").mkdir(parents=True)
    shutil.copy(EXAMPLES_DIR / "sample" / "00003.jpg", failed / "00003.jpg")
    ann = json.loads((EXAMPLES_DIR / "sample" / "00003.json").read_text())
    (failed / "00003.json").write_text(json.dumps(dict(list(ann.items())[:2])))
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
        if only in (None, "sample"):
            session(browser, EXAMPLES_DIR / "sample", tmp / "edits", [
                ("workspace_synthetic", "00006", select_leftmost),
                ("workspace_wc14", "wc14_trainval_16", select_leftmost),
                ("workspace_zoomed", "00006", zoom_on_densest),
                ("view_3d", "00006", three_d),
            ], detect=True)
        if only in (None, "failed"):
            session(browser, failed, tmp / "edits2", [("failed_frame", "00003", None)])
        if only in (None, "clip"):
            session(browser, tmp / "clip", tmp / "edits3", [("workspace_clip", "clip11-IMG_0012", clip_calibrated)])
        if only in (None, "shots"):
            session(browser, tmp / "clip", tmp / "edits4", [("timeline_shots", "clip11-IMG_0012", shot_model)])
        browser.close()
    shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
