"""``pnlviz detect`` (the light default model) on an idle and on a busy machine, per thread setting.

    python benchmarks/bench_detect_threads.py [--frames 20] [--loads 0 1 2] [--threads 0 1 2]

For each number of busy processes beside it (``while True: pass``; this machine has 2 cores, so 1
takes a core and 2 take both) and each ``--threads`` value (0: what ``pnlviz detect`` uses when
not told), runs ``pnlviz detect`` on the bundled sample's images in a child process and prints
the wall time per frame of the detection loop (torch and the model load are left out: the
command prints its own rate) and the child's peak memory.
"""

from __future__ import annotations

import argparse
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pnlviz import EXAMPLES_DIR


def run(data: Path, out: Path, threads: int) -> tuple[float, float]:
    """(ms per frame, peak MB) of one ``pnlviz detect`` run."""
    cmd = [sys.executable, "-m", "pnlviz.cli", "detect", "--data", str(data), "--out", str(out), "--no-progress"]
    if threads:
        cmd += ["--threads", str(threads)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
    peak = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    m = re.search(r"\(([\d.]+) ms/frame\)", proc.stdout)
    if m is None:
        raise RuntimeError(f"no rate in the output of {' '.join(cmd)}:\n{proc.stdout}\n{proc.stderr}")
    return float(m.group(1)), peak


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--loads", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--threads", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="pnlviz-bench-"))
    try:
        data = tmp / "frames"
        data.mkdir()
        for img in sorted((EXAMPLES_DIR / "sample").glob("*.jpg"))[: args.frames]:
            shutil.copy(img, data / img.name)
        print(f"pnlviz detect, light default model, {len(list(data.glob('*.jpg')))} frames")
        print("busy processes | --threads | ms per frame | peak MB")
        for load in args.loads:
            burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(load)]
            try:
                time.sleep(0.5)
                for threads in args.threads:
                    ms, peak = run(data, tmp / "preds.zip", threads)
                    label = str(threads) if threads else "default"
                    print(f"{load} | {label} | {ms:.0f} | {peak:.0f}", flush=True)
            finally:
                for b in burners:
                    b.kill()
                    b.wait()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
