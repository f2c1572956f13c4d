"""Calibration speed and quality on the real data in ../shared/data, measured inside the process.

    python benchmarks/bench_calib.py [--shared ../shared] [--frames N]

For each input (WC14 half from the published PnLCalib detections; SN22 subset from the human
annotations) and each setting (full voting without PnL; with PnL; with PnL + focal + k1, the
default), prints ms per frame (median, p90) of ``calibrate()`` alone (inputs prepared beforehand,
one core: run it with ``taskset -c 0``), JaC@5/10/20, completeness and final score under the
metric that equals the official evaluator, and the peak memory of the process.

The protocol, printed first (:data:`PROTOCOL`): both sets are the development halves; which of
their frames were looked at while tuning is said there.
"""

from __future__ import annotations

import argparse
import resource
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.inputs import observations_from_annotation, observations_from_predictions
from pnlviz.data import open_dataset, read_predictions
from pnlviz.metrics.soccernet import evaluate_dataset

PROTOCOL = """protocol: the development halves in ../shared/data (WC14 test half: 93 frames from the
published PnLCalib detections; SN22 test subset: 400 frames from the human line annotations); the
held-out halves are measured elsewhere, with this same script. One setting for every benchmark:
CalibParams() as written in pnlviz/calib/calibrate.py (the rows below switch PnL, focal and k1
only), no threshold per dataset. Looked at while tuning: every frame of both sets. The engine's
settings (alpha, the gates, the k1 cap, the final loss, the prior search, the class tolerance,
the border aim, the classes that fit without the derived keypoints, the second gate, the points
no paint marks held to their marking, the candidates' ranking tolerance) were chosen on these
figures (the camera's height and distance limits checked against these sets' cameras), and
benchmarks/misses.py reads their misses frame by frame: these are development figures, not held-out ones."""

SETTINGS = {
    "no PnL": replace(CalibParams(), pnl=False, refine_focal=False, refine_k1=False),
    "PnL": replace(CalibParams(), refine_focal=False, refine_k1=False),
    "PnL + focal + k1 (default)": CalibParams(),
}


def run(name: str, gt: Path, observations: dict, frames: int) -> None:
    print(f"\n{name}: {len(observations)} frames")
    print(f"{'setting':28s} {'median ms':>9s} {'p90 ms':>7s} {'JaC@5':>7s} {'JaC@10':>7s} {'JaC@20':>7s} {'CR':>6s} {'FS':>6s}")
    for label, params in SETTINGS.items():
        times, cams = [], {}
        for stem, obs in observations.items():
            t0 = time.perf_counter()
            res = calibrate(obs, params)
            times.append(time.perf_counter() - t0)
            if res.ok:
                cams[stem] = res.camera
        s = evaluate_dataset(gt, cams, progress=False)
        print(f"{label:28s} {1e3 * np.median(times):9.1f} {1e3 * np.percentile(times, 90):7.1f} "
              f"{s.jac(5):7.4f} {s.jac(10):7.4f} {s.jac(20):7.4f} {s.completeness:6.3f} {s.final_score:6.3f}")


def _ground_truth(annotations: Path, stems: list[str], frames: int) -> Path:
    """The annotations zip, or with ``--frames`` a copy of it holding only those frames (the
    evaluator counts every annotated frame without a camera as a miss)."""
    if not frames:
        return annotations
    import tempfile
    import zipfile

    gt = Path(tempfile.mkdtemp()) / "gt.zip"
    with zipfile.ZipFile(gt, "w") as zf, zipfile.ZipFile(annotations) as src:
        for s in stems:
            zf.writestr(f"{s}.json", src.read(f"{s}.json"))
    return gt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[2] / "shared")
    ap.add_argument("--frames", type=int, default=0, help="use only the first N frames of each set")
    args = ap.parse_args()
    data = args.shared / "data"
    print(PROTOCOL)

    wc14 = data / "wc14_test_half"
    preds = read_predictions(wc14 / "detections_pnlcalib.zip")
    stems = sorted(preds, key=int)[: args.frames or None]
    run("WC14 half, published PnLCalib detections", _ground_truth(wc14 / "annotations.zip", stems, args.frames),
        {s: observations_from_predictions(preds[s], 960, 540) for s in stems}, args.frames)

    sn22 = data / "sn22_test_subset" / "annotations.zip"
    ds = open_dataset(sn22)
    stems = ds.stems[: args.frames or None]
    t0 = time.perf_counter()
    obs = {s: observations_from_annotation(ds.annotation(s), 960, 540)[0] for s in stems}
    label_ms = 1e3 * (time.perf_counter() - t0) / len(stems)
    run(f"SN22 subset, human annotations (keypoint labels: {label_ms:.1f} ms/frame, not included)",
        _ground_truth(sn22, stems, args.frames), obs, args.frames)
    print(f"\npeak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
