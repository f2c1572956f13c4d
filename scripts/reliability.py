"""Try pnlviz the way an unlucky user and an attacker would, and write what happens to
docs/reliability.md.

    python scripts/reliability.py [--kill-rounds 20] [--no-browser]

1. every batch command on a catalogue of bad inputs (each run a real ``pnlviz`` process):
   exit code, traceback or not, the bad file named in one line, the good frames still done;
2. ``kill -9`` in the middle of bursts of edits: every acknowledged edit on disk, nothing damaged;
3. concurrent edits: threads of the app's edit path, and two real browser tabs dragging points
   on the same frame at once (headless Chromium);
4. damaged edit records: moved aside, the server starts, the frame shows its source labels;
5. requests from foreign pages and hosts, and without the token.

Everything runs in a temporary folder; the repository is only written at docs/reliability.md.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import zipfile
import zlib
from pathlib import Path

import cv2
import numpy as np

from pnlviz import EXAMPLES_DIR, REPO_ROOT

SAMPLE = EXAMPLES_DIR / "sample"
GOOD = ("00000", "00001", "00002")
OUT = REPO_ROOT / "docs" / "reliability.md"


# ------------------------------------------------------------------------------ bad inputs
def frames(dest: Path, stems=GOOD, images=True, cameras=False) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    for stem in stems:
        shutil.copy(SAMPLE / f"{stem}.json", dest / f"{stem}.json")
        if images:
            shutil.copy(SAMPLE / f"{stem}.jpg", dest / f"{stem}.jpg")
        if cameras:
            (dest / "cameras").mkdir(exist_ok=True)
            shutil.copy(SAMPLE / "cameras" / f"camera_{stem}.json", dest / "cameras" / f"camera_{stem}.json")
    return dest


def zipped(folder: Path, zpath: Path) -> Path:
    with zipfile.ZipFile(zpath, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                zf.write(p, p.relative_to(folder).as_posix())
    return zpath


def patch_member(zpath: Path, member: str, *, first_byte=None, flags=None, size=None) -> None:
    """Damage one member: its first compressed byte, its flags or its declared size."""
    with zipfile.ZipFile(zpath) as zf:
        info = zf.getinfo(member)
    data = bytearray(zpath.read_bytes())
    spots = [(info.header_offset, 22, 6)]
    pos = data.find(b"PK\x01\x02")
    while pos >= 0:
        n = struct.unpack_from("<H", data, pos + 28)[0]
        if data[pos + 46:pos + 46 + n] == member.encode():
            spots.append((pos, 24, 8))
        pos = data.find(b"PK\x01\x02", pos + 4)
    for at, size_at, flags_at in spots:
        if size is not None:
            struct.pack_into("<I", data, at + size_at, size)
        if flags is not None:
            struct.pack_into("<H", data, at + flags_at, flags)
    if first_byte is not None:
        n, m = struct.unpack_from("<HH", data, info.header_offset + 26)
        data[info.header_offset + 30 + n + m] = first_byte
    zpath.write_bytes(bytes(data))


def huge_png(path: Path, w=30000, h=30000) -> None:
    ok, buf = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))
    data = bytearray(buf.tobytes())
    struct.pack_into(">II", data, 16, w, h)
    struct.pack_into(">I", data, 29, zlib.crc32(bytes(data[12:29])))
    path.write_bytes(bytes(data))


def _write(name: str, content: bytes | str):
    """A maker that replaces one file of the dataset with ``content``."""
    def make(d: Path) -> str:
        data = content if isinstance(content, bytes) else content.encode()
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(data)
        return Path(name).name
    return make


def _huge_image(d: Path) -> str:
    (d / "00001.jpg").unlink()
    huge_png(d / "00001.png")
    return "00001.png"


def _name_not_utf8(d: Path) -> str:
    with open(os.path.join(os.fsencode(d), b"\xff.json"), "wb") as f:
        f.write((SAMPLE / "00003.json").read_bytes())
    return "\\xff.json"  # how messages print it


def _duplicate(src: str, dst: str):
    def make(d: Path) -> str:
        if dst.endswith(".png"):
            cv2.imwrite(str(d / dst), cv2.imread(str(d / src)))
        else:
            shutil.copy(d / src, d / dst)
        return dst
    return make


TWO_POINTS = '[{"x": 0.1, "y": 0.2}, {"x": 0.3, "y": 0.2}]'
#: bad input -> a maker that damages a copy of three good frames and returns the bad file's name
BAD_INPUTS = {
    "broken JSON": _write("00001.json", '{"Side line top": [{"x": 0.1'),
    "annotation is a list": _write("00001.json", "[1, 2]"),
    "unknown class": _write("00001.json", '{"Side lin top": ' + TWO_POINTS + "}"),
    "NaN coordinate": _write("00001.json", '{"Side line top": [{"x": NaN, "y": 0.2}, {"x": 0.3, "y": 0.2}]}'),
    "coordinates in pixels": _write("00001.json", '{"Side line top": [{"x": 512, "y": 300}, {"x": 700, "y": 300}]}'),
    "not UTF-8 inside": _write("00001.json", b'{"Side line top\xff": []}'),
    "truncated JPEG": _write("00001.jpg", (SAMPLE / "00001.jpg").read_bytes()[:600]),
    "empty image": _write("00001.jpg", b""),
    "30000x30000 PNG": _huge_image,
    "file name not UTF-8": _name_not_utf8,
    "duplicate stem .json/.JSON": _duplicate("00001.json", "00001.JSON"),
    "duplicate stem .jpg/.png": _duplicate("00001.jpg", "00001.png"),
    "broken camera": _write("cameras/camera_00001.json", '{"pan_degrees": 1'),
    "camera missing a key": _write("cameras/camera_00001.json", '{"pan_degrees": 1}'),
}
#: damage done to member 00001.json of a zipped dataset
BAD_MEMBERS = {
    "corrupt deflate in a zip": dict(first_byte=0xFF),
    "encrypted zip member": dict(flags=1),
    "zip member claiming 2 GiB": dict(size=2 ** 31),
}


def make_cases(root: Path) -> dict[str, tuple[Path, str]]:
    """name -> (dataset, the bad file's name as it appears in messages)."""
    cases = {}
    for name, make in BAD_INPUTS.items():
        d = frames(root / name, cameras=True)
        cases[name] = (d, make(d))
    for name, damage in BAD_MEMBERS.items():
        z = zipped(frames(root / f"{name} (files)"), root / f"{name}.zip")
        patch_member(z, "00001.json", **damage)
        cases[name] = (z, "00001.json")
    return cases


def pnlviz(*args: str, cwd: Path, timeout: float = 600) -> tuple[int, str, str]:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    p = subprocess.run([sys.executable, "-m", "pnlviz.cli", *args], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout, env=env, errors="backslashreplace")
    return p.returncode, p.stdout, p.stderr


def command_runs(data: Path, work: Path) -> dict[str, list[str]]:
    """command -> argv, each writing into ``work``."""
    cams = work / "cams.zip"
    return {
        "validate": ["validate", "--data", str(data), "--images"],
        "calibrate": ["calibrate", "--data", str(data), "--out", str(cams), "--no-progress"],
        "eval": ["eval", "--gt", str(data), "--pred", str(REFERENCE_CAMERAS), "--no-progress"],
        "labels": ["labels", "--data", str(data), "--out", str(work / "labels")],
        "sheet": ["sheet", "--data", str(data), "--out", str(work / "sheet.png"), "-n", "8"],
        "export": ["export", "--data", str(data), "--out", str(work / "export"), "--all", "--edits", str(work / "edits")],
        "detect": ["detect", "--data", str(data), "--out", str(work / "preds.zip"), "--no-progress", "--threads", "1"],
    }


REFERENCE_CAMERAS: Path  # set in main: the sample's cameras of the good frames, zipped


def went_on(command: str, work: Path) -> bool | None:
    """Did the command still do the good frames? None where there is nothing to look at."""
    if command == "calibrate":
        return (work / "cams.zip").is_file() and len(zipfile.ZipFile(work / "cams.zip").namelist()) >= 2
    if command == "detect":
        return (work / "preds.zip").is_file() and len(zipfile.ZipFile(work / "preds.zip").namelist()) >= 2
    if command == "labels":
        return len(list((work / "labels").glob("*.json"))) >= 2
    if command == "sheet":
        return (work / "sheet.png").is_file()
    if command == "export":
        return len(list((work / "export" / "keypoints").glob("*.json"))) >= 2
    return None


def bad_input_section(tmp: Path) -> list[str]:
    global REFERENCE_CAMERAS
    REFERENCE_CAMERAS = tmp / "reference_cameras.zip"
    with zipfile.ZipFile(REFERENCE_CAMERAS, "w") as zf:
        for stem in GOOD + ("00003",):
            zf.write(SAMPLE / "cameras" / f"camera_{stem}.json", f"camera_{stem}.json")
    cases = make_cases(tmp / "cases")
    commands = list(command_runs(tmp, tmp))
    totals = {"runs": 0, "tracebacks": 0, "named": 0, "went_on": 0, "went_on_checked": 0, "signals": 0}
    matrix, messages = [], []
    for name, (data, bad) in cases.items():
        cells, message = [], ""
        for command in commands:
            work = tmp / "work" / f"{totals['runs']}"
            work.mkdir(parents=True)
            code, out, err = pnlviz(*command_runs(data, work)[command], cwd=work)
            text = (out + err).replace(str(data.parent) + "/", "")  # paths relative to the cases' folder
            traceback = "Traceback" in text or code < 0
            named = sum(bad in line for line in text.splitlines())
            on = went_on(command, work)
            totals["runs"] += 1
            totals["tracebacks"] += traceback
            totals["signals"] += code < 0
            totals["named"] += named >= 1
            if on is not None:
                totals["went_on_checked"] += 1
                totals["went_on"] += on
            if command == "validate":
                message = next((ln.strip() for ln in text.splitlines() if bad in ln), "")
            cells.append(f"{code}{' TRACEBACK' if traceback else ''} {'named' if named else '-'}"
                         f"{'' if on is None else ', rest done' if on else ', REST NOT DONE'}")
            shutil.rmtree(work, ignore_errors=True)
        matrix.append(f"| {name} | " + " | ".join(cells) + " |")
        messages.append(f"| {name} | {message[:140].replace('|', '/')} |")
    # outputs that would land on or inside the inputs
    d = frames(tmp / "outputs")
    empty = tmp / "empty"
    empty.mkdir()
    misuse = {
        "detect --out D/00001.zip (over an annotation)": ["detect", "--data", str(d), "--out", str(d / "00001.zip")],
        "detect --out preds.json (not a zip)": ["detect", "--data", str(d), "--out", str(tmp / "preds.json")],
        "detect --out D/preds.zip (inside the dataset)": ["detect", "--data", str(d), "--out", str(d / "preds.zip")],
        "calibrate --out D/cams.zip": ["calibrate", "--data", str(d), "--out", str(d / "cams.zip")],
        "labels --out D": ["labels", "--data", str(d), "--out", str(d)],
        "sheet --out D/sheet.png": ["sheet", "--data", str(d), "--out", str(d / "sheet.png")],
        "export --out D/x.zip": ["export", "--data", str(d), "--out", str(d / "x.zip")],
        "eval --csv over --gt annotation": ["eval", "--gt", str(d), "--pred", str(REFERENCE_CAMERAS), "--csv",
                                            str(d / "00001.json")],
        "empty folder": ["calibrate", "--data", str(empty), "--out", str(tmp / "c.zip")],
        "eval, no camera matches": ["eval", "--gt", str(d), "--pred", str(zipped_empty(tmp))],
    }
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    misuse_rows = []
    for name, argv in misuse.items():
        code, out, err = pnlviz(*argv, cwd=tmp)
        changed = {p.name: p.read_bytes() for p in d.iterdir()} != before
        totals["runs"] += 1
        totals["tracebacks"] += "Traceback" in out + err
        last = (err.strip().splitlines() or [""])[-1].replace(str(tmp) + "/", "")
        misuse_rows.append(f"| {name} | {code} | {'yes' if changed else 'no'} | {last[:140].replace('|', '/')} |")
    return [
        "## 1. Bad inputs to the batch commands",
        "",
        f"{len(cases)} kinds of bad input, each given to {len(commands)} commands, plus {len(misuse)} misuses: "
        f"**{totals['runs']} runs, {totals['tracebacks']} with a traceback, {totals['signals']} killed by a signal**. "
        f"The bad file is named in {totals['named']} of the {totals['runs'] - len(misuse)} bad-input runs (the "
        f"others are commands that never read that file: `calibrate` needs only an image's size, `detect` no "
        f"annotation); where there is output to look at, the good frames were done in {totals['went_on']} of "
        f"{totals['went_on_checked']} runs. Each dataset holds three good frames and the bad file.",
        "",
        "Each cell: exit code, whether the bad file is named (one line), whether the good frames were done.",
        "",
        "| bad input | " + " | ".join(f"`{c}`" for c in commands) + " |",
        "|---|" + "---|" * len(commands),
        *matrix,
        "",
        "What `pnlviz validate --images` says about each:",
        "",
        "| bad input | message |",
        "|---|---|",
        *messages,
        "",
        "Outputs that would land on or inside an input (the dataset must be unchanged), and nothing to do:",
        "",
        "| misuse | exit | dataset changed | message |",
        "|---|---|---|---|",
        *misuse_rows,
        "",
    ]


def zipped_empty(tmp: Path) -> Path:
    z = tmp / "no_match.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("camera_nothing_like_it.json", (SAMPLE / "cameras" / "camera_00000.json").read_text())
    return z


# ------------------------------------------------------------------------------ kill -9
BURST = r"""
import sys
from pnlviz.app.state import AppState
st = AppState(sys.argv[1], edits=sys.argv[2])
kps = {s: [int(k) for k in st.view(s).observations.kp_ids[:6]] for s in ("00000", "00001", "00002")}
n = 0
while True:
    for s, ids in kps.items():
        for kid in ids:
            n += 1
            x, y = 100.0 + (n % 500), 50.0 + (n % 300)
            print(f"try {s} {kid} {x} {y}", flush=True)
            st.move_keypoint(s, kid, x, y)
            print(f"ack {s} {kid} {x} {y}", flush=True)
"""


def kill_section(tmp: Path, rounds: int) -> list[str]:
    from pnlviz.app.state import AppState

    data = frames(tmp / "kill", cameras=False)
    edits = tmp / "kill.edits"
    rng = random.Random(0)
    acked_total = lost = damaged = tmp_left = 0
    for _ in range(rounds):
        p = subprocess.Popen([sys.executable, "-c", BURST, str(data), str(edits)], stdout=subprocess.PIPE, text=True)
        acks: list[str] = []
        reader = threading.Thread(target=lambda: acks.extend(iter(p.stdout.readline, "")), daemon=True)
        reader.start()
        time.sleep(rng.uniform(2.5, 4.0))  # the child needs ~2 s to start and calibrate
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        reader.join(timeout=5)
        acked, tried = {}, {}  # (stem, id) -> the last value acknowledged / the last one begun
        for line in acks:
            kind, s, kid, x, y = line.split()
            (acked if kind == "ack" else tried)[(s, kid)] = [float(x), float(y)]
        acked_total += sum(line.startswith("ack ") for line in acks)
        tmp_left += len(list((edits / "frames").glob(".*.tmp")))
        st = AppState(data, edits=edits)
        damaged += len(st.edits.warnings)
        for key, xy in acked.items():  # on disk: that value, or the one of an edit the kill cut short
            lost += st.edits.get(key[0]).get("keypoints", {}).get(key[1]) not in (xy, tried.get(key))
        st.close()
    return [
        "## 2. `kill -9` during bursts of edits",
        "",
        f"{rounds} rounds: a process edits keypoints of three frames as fast as it can (each edit autosaved) "
        f"and is killed with SIGKILL after 2.5-4 s. Then a new app opens the same edits folder.",
        "",
        "| rounds | edits acknowledged | keypoints whose last acknowledged edit is not on disk (nor a newer one "
        "the kill cut short) | damaged records | temporary files left by the kills (removed on the next start) |",
        "|---|---|---|---|---|",
        f"| {rounds} | {acked_total} | {lost} | {damaged} | {tmp_left} |",
        "",
    ]


# ------------------------------------------------------------------------------ concurrency
def threads_section(tmp: Path) -> list[str]:
    from pnlviz.app.state import AppState

    data = frames(tmp / "threads")
    st = AppState(data, edits=tmp / "threads.edits")
    jobs = [(s, int(k), 100.0 + i, 60.0 + i) for s in GOOD for i, k in enumerate(st.view(s).observations.kp_ids[:16])]
    barrier = threading.Barrier(12)

    def work(chunk):
        barrier.wait()
        for s, kid, x, y in chunk:
            st.move_keypoint(s, kid, x, y)

    ts = [threading.Thread(target=work, args=(jobs[i::12],)) for i in range(12)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    landed = sum(json.loads((st.edits.frames / f"{s}.json").read_text())["keypoints"].get(str(k)) == [x, y]
                 for s, k, x, y in jobs)
    st.close()
    return [f"- threads: {len(jobs)} keypoint edits on {len(GOOD)} frames from 12 threads at once: "
            f"**{landed} of {len(jobs)} on disk, each on its own frame**."]


def browser_section(tmp: Path, drags_per_tab: int = 8) -> list[str]:
    """Two real tabs on the same frame drag different keypoints in turns, as fast as the browser
    takes them (each release recalibrates the frame, which moves the other tab's points: every
    drag aims at where its point is on that tab's screen right then). The points are 40 px apart
    at least, so that a dragged one never lands on the next one to be grabbed."""
    from playwright.sync_api import sync_playwright

    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    data = frames(tmp / "tabs", cameras=True)
    st = AppState(data, edits=tmp / "tabs.edits")
    app = PnlvizApp(st, port=free_port())
    flags = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync"]

    def canvas_box(page) -> dict:
        return max((c.bounding_box() for c in page.locator("canvas[data-engine]").all()),
                   key=lambda b: b["width"] * b["height"])  # the viewer's (three.js marks it)

    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=flags)
            tabs = []
            for _ in range(2):  # one at a time, so that each page is paired with its own session
                page = browser.new_page(viewport={"width": 1400, "height": 900})
                page.goto(app.url)
                page.get_by_text("focal").first.wait_for(timeout=60000)
                deadline = time.time() + 30
                while time.time() < deadline and not any(
                        t.view_control.css_canvas is not None and all(t is not s for _, s in tabs) for t in app.tabs()):
                    time.sleep(0.2)
                session = next(t for t in app.tabs() if all(t is not s for _, s in tabs))
                tabs.append((page, session))
            time.sleep(2.0)
            obs = tabs[0][1].view().observations
            dragged, spots = [], []  # leftmost first (away from the panel), none within 40 px of another
            for i in np.argsort(obs.kp_xy[:, 0]):
                if len(dragged) < 2 * drags_per_tab and all(np.hypot(*(obs.kp_xy[i] - p)) > 40 for p in spots):
                    dragged.append(int(obs.kp_ids[i]))
                    spots.append(obs.kp_xy[i])
            for n, kid in enumerate(dragged):
                page, session = tabs[n % 2]
                page.bring_to_front()  # a page in the background does not draw (nor pick)
                session.flush()
                box = canvas_box(page)
                nodes = session.workspace.points["keypoints"]
                view = session.view_control
                x0, y0 = view.view2d.to_screen(nodes.uv[nodes.keys.index(kid)], view.canvas)
                x0, y0 = box["x"] + x0, box["y"] + y0
                page.mouse.move(x0, y0)
                page.mouse.down()
                page.mouse.move(x0 + 4, y0 + 5, steps=3)
                page.mouse.move(x0 + 8, y0 + 10, steps=3)
                page.mouse.up()
            time.sleep(4.0)
            grabbed = sum(s.editor.grabs for _, s in tabs)
            released = sum(s.editor.releases for _, s in tabs)
            browser.close()
        stem = st.stems[st.first_index]
        saved = st.edits.get(stem).get("keypoints") or {}
        landed = sum(str(kid) in saved for kid in dragged)
        others = [s for s in st.stems if s != stem and st.edits.get(s)]
    finally:
        app.stop()
        st.close()
    return [f"- two browser tabs (headless Chromium, real mouse drags of the points themselves) on the same frame, "
            f"dragging in turns without waiting for each other: {len(dragged)} drags, {grabbed} grabbed a point, "
            f"{released} releases reached the server, **{landed} edits on disk**, {len(others)} edits on another "
            f"frame."]


# ------------------------------------------------------------------------------ damaged records
DAMAGED = {
    "a list": "[1, 2]", "an id that is not a number": '{"keypoints": {"abc": [1, 2]}}',
    "id 999": '{"keypoints": {"999": [1, 2]}}', "NaN": '{"keypoints": {"5": [NaN, 2]}}',
    "Infinity": '{"keypoints": {"5": [Infinity, 2]}}', "unknown review": '{"review": "approved"}',
    "bad annotation": '{"annotation": {"Nope": [{"x": 0.1, "y": 0.2}]}}', "broken JSON": '{"review": "acc',
}


def damaged_section(tmp: Path) -> list[str]:
    from pnlviz.app.state import AppState

    rows = []
    for i, (name, text) in enumerate(DAMAGED.items()):
        data = frames(tmp / f"damaged{i}")
        edits = tmp / f"damaged{i}.edits"
        (edits / "frames").mkdir(parents=True)
        (edits / "frames" / "00001.json").write_text(text)
        code, out, err = pnlviz("export", "--data", str(data), "--edits", str(edits), "--out", str(tmp / f"x{i}"),
                                "--all", cwd=tmp)
        st = AppState(data, edits=edits)
        moved = (edits / "frames" / "00001.json.damaged").is_file()
        ok = st.view("00001").result.ok
        st.close()
        rows.append(f"| {name} | {code}{' (traceback)' if 'Traceback' in err else ''} | "
                    f"{'yes' if moved else 'no'} | {'yes' if ok else 'no'} |")
    return ["## 4. Damaged edit records", "",
            "| record | `pnlviz export` exit | moved aside by the app | frame calibrated from its source labels |",
            "|---|---|---|---|", *rows, ""]


# ------------------------------------------------------------------------------ access
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def access_section(tmp: Path) -> list[str]:
    import websockets.sync.client

    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    def handshake(port, **headers):
        try:
            with websockets.sync.client.connect(f"ws://127.0.0.1:{port}/", additional_headers=headers,
                                                subprotocols=["viser-v1.1.1"], origin=None, open_timeout=10):
                return "accepted"
        except websockets.exceptions.InvalidStatus as e:
            return f"refused ({e.response.status_code})"

    def http(url, headers=None):
        try:
            with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=10) as r:
                return f"{r.status}"
        except urllib.error.HTTPError as e:
            return f"refused ({e.code})"

    rows = []
    for host in ("127.0.0.1", "0.0.0.0"):
        data = frames(tmp / f"access_{host}")
        st = AppState(data)
        app = PnlvizApp(st, host=host, port=free_port())
        port, token = app.policy.port, app.policy.token
        cookie = {"Cookie": f"pnlviz_token={token}"} if token else {}
        tries = {
            "the app's own page": handshake(port, Origin=f"http://127.0.0.1:{port}", **cookie),
            "a page on another local port": handshake(port, Origin="http://127.0.0.1:9999", **cookie),
            "a page on another site": handshake(port, Origin="https://evil.example", **cookie),
            "a client with no token": handshake(port, Origin=f"http://127.0.0.1:{port}"),
            "page load under another host name (DNS rebinding)": http(f"http://127.0.0.1:{port}/",
                                                                       {"Host": f"evil.example:{port}"}),
            "page load without the token": http(f"http://127.0.0.1:{port}/"),
            "page load with the printed URL": http(app.url),
        }
        for what, result in tries.items():
            rows.append(f"| `--host {host}` | {what} | {result} |")
        app.stop()
        st.close()
    return ["## 5. Who may connect", "",
            "| server | request | result |", "|---|---|---|", *rows, ""]


# ------------------------------------------------------------------------------ round two
def hostile_section(tmp: Path, commit: str) -> list[str]:
    """Section 6: files that are not files, outputs that are not files, full disks, impossible
    values, training failures (:mod:`hostile`, also runnable alone)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import hostile

    root = tmp / "hostile"
    root.mkdir()
    root.chmod(0o755)
    try:
        results = hostile.run_all(root, None, 60.0)
    finally:
        hostile.unmount_all()
    before = REPO_ROOT / "docs" / "reliability_before.json"
    return hostile.section(results, json.loads(before.read_text()) if before.is_file() else None, commit)


# ------------------------------------------------------------------------------ main
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kill-rounds", type=int, default=20)
    ap.add_argument("--no-browser", action="store_true", help="skip the two-tab browser run")
    ap.add_argument("--no-hostile", action="store_true", help="skip section 6 (scripts/hostile.py, ~15 min)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT, capture_output=True,
                            text=True).stdout.strip()
    try:
        lines = ["# Reliability", "",
                 f"What `python scripts/reliability.py` found on {time.strftime('%Y-%m-%d')} (commit {commit}); "
                 "regenerate it with that command. Every run is a real process on files made for the purpose.", ""]
        t0 = time.time()
        lines += bad_input_section(tmp)
        print(f"bad inputs: {time.time() - t0:.0f} s", flush=True)
        lines += kill_section(tmp, args.kill_rounds)
        print(f"kill -9: {time.time() - t0:.0f} s", flush=True)
        lines += ["## 3. Concurrent edits", "", *threads_section(tmp)]
        if not args.no_browser and shutil.which("chromium"):
            lines += browser_section(tmp)
        lines += [""]
        print(f"concurrency: {time.time() - t0:.0f} s", flush=True)
        lines += damaged_section(tmp)
        lines += access_section(tmp)
        if not args.no_hostile:
            lines += hostile_section(tmp, commit)
        OUT.write_text("\n".join(lines) + "\n")
        print(f"wrote {OUT} ({time.time() - t0:.0f} s)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
