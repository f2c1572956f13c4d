"""Screenshots of the app for the README, taken in headless Chromium (Debian's `chromium`).

    python scripts/screenshots.py        # writes docs/screenshots/*.jpg

Edits go to a temporary folder: the bundled sample is not touched.
"""

from __future__ import annotations

import json
import shutil
import socket
import tempfile
import time
from pathlib import Path

import cv2
from playwright.sync_api import sync_playwright

from pnlviz import EXAMPLES_DIR, REPO_ROOT
from pnlviz.app.server import PnlvizApp
from pnlviz.app.state import AppState

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


def session(browser, data: Path, edits: Path, shots: list[tuple[str, str, bool]]) -> None:
    app = PnlvizApp(AppState(data, edits=edits), port=free_port())
    try:
        page = browser.new_page(viewport={"width": 1600, "height": 900})
        page.goto(app.url)
        page.get_by_text("Calibration").first.wait_for(timeout=30000)
        tab = app.tabs()[0]
        for name, stem, camera_view in shots:
            tab.goto(app.state.find(stem))
            time.sleep(1.0)
            if camera_view:
                page.get_by_role("button", name="camera view").click()
            shoot(page, name)
        page.close()
    finally:
        app.stop()
        app.state.close()


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp())
    # a frame whose annotation holds two lines only: too little to calibrate
    failed = tmp / "failed"
    (failed / "cameras").mkdir(parents=True)
    shutil.copy(EXAMPLES_DIR / "sample" / "00003.jpg", failed / "00003.jpg")
    ann = json.loads((EXAMPLES_DIR / "sample" / "00003.json").read_text())
    (failed / "00003.json").write_text(json.dumps(dict(list(ann.items())[:2])))
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
        session(browser, EXAMPLES_DIR / "sample", tmp / "edits", [
            ("view_3d", "00006", False),
            ("camera_view_synthetic", "00006", True),
            ("camera_view_wc14", "wc14_trainval_16", True),
            ("camera_view_sn22_annotation", "sn22_00250", True),
        ])
        session(browser, failed, tmp / "edits2", [("failed_frame", "00003", False)])
        browser.close()
    shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
