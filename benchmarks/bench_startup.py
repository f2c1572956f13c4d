"""The README's first command, started again and again with a browser connecting: does it start
clean every time, and how long until the URL, the first frame and the detections?

    python benchmarks/bench_startup.py [--runs 30] [--load 2] [--data DIR]

Each run starts ``pnlviz serve`` (the bundled sample and the light default detector unless
``--data``), opens the printed URL in headless Chromium, waits for the frame on screen and for
the background detections, checks the server is alive and has not loaded torch, then stops it
with SIGTERM and checks it exited 0 with no traceback. ``--load N`` keeps N busy processes
running meanwhile (the machine has 2 cores: 2 means fully loaded). Edits go to a temporary
folder, the same for every run (each run must release it for the next). Prints one line per
run and a summary with the servers' and detector processes' peak memory (VmHWM).
"""

from __future__ import annotations

import argparse
import re
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def peak_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
    return [int(p) for p in out]


def one_run(browser, args, edits: Path) -> dict:
    port = free_port()
    cmd = [sys.executable, "-m", "pnlviz.cli", "serve", "--port", str(port), "--edits", str(edits)]
    if args.data:
        cmd += ["--data", str(args.data)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    run = {"ok": False, "why": ""}
    try:
        for line in proc.stdout:
            if "open http" in line:
                run["url_s"] = time.perf_counter() - t0
                break
        else:
            run["why"] = "exited before printing its URL"
            return run
        page = browser.new_page(viewport={"width": 1600, "height": 900})
        page.goto(f"http://127.0.0.1:{port}/")
        page.get_by_text("computed in").first.wait_for(timeout=120_000)
        run["frame_s"] = time.perf_counter() - t0
        page.get_by_text(re.compile(r"calibrated from: (both|detections)")).first.wait_for(timeout=180_000)
        run["detections_s"] = time.perf_counter() - t0
        page.close()
        alive = proc.poll() is None
        torch = "libtorch" in Path(f"/proc/{proc.pid}/maps").read_text() if alive else None
        run["server_mb"] = peak_mb(proc.pid) if alive else float("nan")
        kids = [c for c in children(proc.pid) if "libtorch" in Path(f"/proc/{c}/maps").read_text()]
        run["detector_mb"] = max((peak_mb(c) for c in kids), default=float("nan"))
        if not alive:
            run["why"] = f"died (exit {proc.returncode})"
        elif torch:
            run["why"] = "the server process loaded torch"
    except Exception as exc:  # noqa: BLE001 - a failed run is counted and described, the next one goes on
        run["why"] = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
    finally:
        if proc.poll() is None:
            proc.terminate()
        _, err = proc.communicate(timeout=60)
    if not run["why"] and proc.returncode != 0:
        run["why"] = f"exit code {proc.returncode} after SIGTERM"
    if not run["why"] and "Traceback" in err:
        run["why"] = "traceback on stderr:\n    " + "\n    ".join(err.strip().splitlines()[-12:])
    run["ok"] = not run["why"]
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--load", type=int, default=0, help="busy processes running meanwhile")
    ap.add_argument("--data", type=Path, help="dataset (default: the bundled sample)")
    args = ap.parse_args()
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    edits = Path(tempfile.mkdtemp()) / "edits"
    runs = []
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
            for i in range(args.runs):
                run = one_run(browser, args, edits)
                runs.append(run)
                times = ", ".join(f"{k[:-2]} {run[k]:.1f} s" for k in ("url_s", "frame_s", "detections_s") if k in run)
                print(f"run {i + 1:2d}: {'clean' if run['ok'] else 'FAILED: ' + run['why']}  ({times})", flush=True)
            browser.close()
    finally:
        for b in burners:
            b.kill()
        shutil.rmtree(edits.parent, ignore_errors=True)
    ok = [r for r in runs if r["ok"]]
    print(f"\n{len(ok)}/{len(runs)} clean starts with a client connecting ({args.load} busy processes beside)")
    for key, what in (("url_s", "URL printed"), ("frame_s", "first frame in the browser"),
                      ("detections_s", "detections shown")):
        values = [r[key] for r in ok]
        if values:
            print(f"  {what}: median {statistics.median(values):.1f} s, max {max(values):.1f} s after the start")
    for key, what in (("server_mb", "server process"), ("detector_mb", "detector process")):
        values = [r[key] for r in ok if r[key] == r[key]]
        if values:
            print(f"  peak memory of the {what}: {max(values):.0f} MB")


if __name__ == "__main__":
    main()
