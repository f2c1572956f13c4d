"""Scale: a 23,000-frame SN23-sized dataset calibrated on 1 and 2 workers, and the light detector
on 1,000 frames on 1 and 2 workers, and an export of 4,000 frames on 1 and 2 workers; with
``--qa``, the label-error finder over the 23,000 frames on 2 worker processes and on 2 dask workers.

    python benchmarks/bench_scale.py [--frames 23000] [--detect 1000] [--export 4000]
                                     [--skip-calibrate] [--skip-detect] [--qa]

* Calibration from labels: a zip of ``--frames`` SoccerNet annotations (the 400 real SN22 test
  annotations of ``../shared/data/sn22_test_subset`` repeated under new stems; no images needed),
  ``pnlviz calibrate`` locally (one process) and with ``--scheduler`` on a local dask cluster of 2
  worker processes. Prints wall time, frames/s, speed-up, and peak memory: of the local process,
  of the command's process and of each worker on the cluster. The two outputs are compared byte
  for byte.
* Detection: ``--detect`` frames (the bundled sample's images, linked under new stems),
  ``pnlviz detect --threads 1`` locally and on the 2-worker cluster (1 torch thread per worker).
* Label QA (``--qa``): ``pnlviz qa --workers 2`` and ``pnlviz qa --scheduler`` on the same
  cluster over the ``--frames`` annotations; wall time, frames/s, peak memory of the command's
  process and its worker processes, and whether the two outputs list the same frames, scores and
  findings (the timings aside).
* Export: ``pnlviz export --all`` of ``--export`` of those annotations (every frame calibrated,
  its label files written), locally and on the cluster; the outputs are compared member by member
  (the manifest's export date left out).

All on this machine: the 2 workers share its 2 cores with the command itself.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _peak_mb_children() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024


def _run(cmd: list[str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return time.perf_counter() - t0, r.stdout


def _same_bytes(a: Path, b: Path) -> bool:
    return a.read_bytes() == b.read_bytes()


def _same_export(a: Path, b: Path) -> bool:
    from pnlviz.pipeline.export import read_export_zip

    return read_export_zip(a) == read_export_zip(b)


def _local_then_cluster(cmd: list[str], outputs: Path, name: str, scheduler: str, chunk: int,
                        local: tuple[str, ...] = (), same=_same_bytes) -> tuple[float, float, float, bool]:
    """``cmd`` once in one process (with ``local`` options) and once on the cluster at
    ``scheduler``: (local s, the peak memory MB of the processes so far, cluster s, whether
    ``same(local output, cluster output)``)."""
    a, b = outputs / f"{name}_local.zip", outputs / f"{name}_cluster.zip"
    t1, _ = _run(cmd + ["--out", str(a), "--no-progress", *local])
    peak = _peak_mb_children()
    t2, _ = _run(cmd + ["--out", str(b), "--no-progress", "--scheduler", scheduler, "--chunk", str(chunk)])
    return t1, peak, t2, same(a, b)


def _same_qa(a: Path, b: Path) -> bool:
    import json

    def rows(path: Path) -> list[dict]:  # each frame's line, its time aside
        return [{k: v for k, v in r.items() if k != "ms"} for r in map(json.loads, path.read_text().splitlines())
                if "stem" in r]

    return rows(a) == rows(b)


def _worker_peaks(client) -> list[float]:
    return sorted(round(v / 1024) for v in client.run(
        lambda: __import__("resource").getrusage(__import__("resource").RUSAGE_SELF).ru_maxrss).values())


def build_annotations(src: Path, n: int, out: Path) -> None:
    with zipfile.ZipFile(src) as z:
        texts = [z.read(name) for name in sorted(z.namelist()) if name.endswith(".json")]
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_STORED) as dst:
        for i in range(n):
            dst.writestr(f"{i:05d}.json", texts[i % len(texts)])


def build_images(n: int, out: Path) -> None:
    from pnlviz import EXAMPLES_DIR

    images = sorted((EXAMPLES_DIR / "sample").glob("0*.jpg"))
    out.mkdir()
    for i in range(n):
        os.symlink(images[i % len(images)], out / f"{i:05d}.jpg")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--frames", type=int, default=23000)
    ap.add_argument("--detect", type=int, default=1000)
    ap.add_argument("--export", type=int, default=4000, help="frames to export (0: no export run)")
    ap.add_argument("--skip-calibrate", action="store_true")
    ap.add_argument("--skip-detect", action="store_true")
    ap.add_argument("--qa", action="store_true", help="the label-error finder over the --frames annotations too")
    args = ap.parse_args(argv)
    try:
        import distributed
    except ImportError:
        print('bench_scale needs dask: pip install -e ".[dask]"', file=sys.stderr)
        return 2
    src = args.shared / "data" / "sn22_test_subset" / "annotations.zip"
    tmp = Path(tempfile.mkdtemp())
    pnlviz = [sys.executable, "-m", "pnlviz"]
    try:
        data = tmp / "sn23_sized.zip"
        build_annotations(src, args.frames, data)
        print(f"dataset: {args.frames} annotations ({data.stat().st_size / 2**20:.0f} MiB zip), no images")
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      silence_logs=50) as c, distributed.Client(c) as client:
            if not args.skip_calibrate:
                t1, local_peak, t2, same = _local_then_cluster(pnlviz + ["calibrate", "--data", str(data)], tmp,
                                                               "calibrate", c.scheduler_address, 64)
                workers = _worker_peaks(client)
                print("| calibrate (from labels) | wall (s) | frames/s | speed-up | peak memory |")
                print("|---|---|---|---|---|")
                print(f"| 1 process | {t1:.0f} | {args.frames / t1:.0f} | 1.00 | {local_peak:.0f} MB |")
                print(f"| 2 dask workers | {t2:.0f} | {args.frames / t2:.0f} | {t1 / t2:.2f} | "
                      f"{' and '.join(f'{w} MB' for w in workers)} per worker |")
                print(f"outputs identical byte for byte: {same}")
            if args.qa:
                a, b = tmp / "qa_local.jsonl", tmp / "qa_cluster.jsonl"
                cmd = pnlviz + ["qa", "--data", str(data), "--no-progress"]
                before = _peak_mb_children()
                q1, _ = _run(cmd + ["--out", str(a), "--workers", "2"])
                q1_peak = _peak_mb_children()
                q2, _ = _run(cmd + ["--out", str(b), "--scheduler", c.scheduler_address, "--chunk", "64"])
                workers = _worker_peaks(client)
                print("| qa (label errors, from labels) | wall (s) | frames/s | peak memory |")
                print("|---|---|---|---|")
                print(f"| 2 worker processes | {q1:.0f} | {args.frames / q1:.0f} | "
                      f"{q1_peak:.0f} MB (largest process so far{'' if q1_peak > before else ': an earlier one'}) |")
                print(f"| 2 dask workers | {q2:.0f} | {args.frames / q2:.0f} | "
                      f"{' and '.join(f'{w} MB' for w in workers)} per worker (since the cluster started) |")
                print(f"same frames, scores and findings: {_same_qa(a, b)}")
            if args.export:
                exports = tmp / "export_set.zip"
                build_annotations(src, args.export, exports)
                cmd = pnlviz + ["export", "--data", str(exports), "--all", "--edits", str(tmp / "edits")]
                e1, e1_peak, e2, same = _local_then_cluster(cmd, tmp, "export", c.scheduler_address, 64,
                                                            same=_same_export)
                workers = _worker_peaks(client)
                print(f"| export --all ({args.export} frames) | wall (s) | frames/s | speed-up |")
                print("|---|---|---|---|")
                print(f"| 1 process | {e1:.0f} | {args.export / e1:.0f} | 1.00 |")
                print(f"| 2 dask workers | {e2:.0f} | {args.export / e2:.0f} | {e1 / e2:.2f} |")
                print(f"outputs identical (manifest date aside): {same}; peak memory: "
                      f"{e1_peak:.0f} MB of the processes so far, worker peaks {workers} MB")
            if not args.skip_detect:
                frames = tmp / "frames"
                build_images(args.detect, frames)
                d1, _, d2, same = _local_then_cluster(pnlviz + ["detect", "--data", str(frames)], tmp, "detect",
                                                      c.scheduler_address, 25, local=("--threads", "1"))
                workers = _worker_peaks(client)
                print("| detect (light model, 960x540 frames) | wall (s) | frames/s | speed-up |")
                print("|---|---|---|---|")
                print(f"| 1 process, 1 thread | {d1:.0f} | {args.detect / d1:.1f} | 1.00 |")
                print(f"| 2 dask workers, 1 thread each | {d2:.0f} | {args.detect / d2:.1f} | {d1 / d2:.2f} |")
                print(f"outputs identical byte for byte: {same}; worker peaks {workers} MB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
