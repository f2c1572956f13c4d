"""Where the calibration misses, frame by frame, and why: the frames of the development sets in
../shared/data that are not perfect at JaC@5, put in classes of failure by what their inputs
show, with what fixing each class would gain.

    python benchmarks/misses.py [--shared ../shared] [--list N]

**Sets** (both are the development halves the engine's figures are reported on; nothing in the
engine was tuned on a per-frame look at them, and these classes are read off the inputs, not
chosen after looking at the ranking): the 93 WC14 test frames calibrated from the published
PnLCalib detections, and the 400 SN22 test frames calibrated from their human line annotations,
both with the default settings at 960x540, scored with the metric that equals the official
evaluator.

**Classes** (the first rule that holds; every frame below 1.0 at JaC@5, or without a camera, is in
exactly one):

1. *no camera*, with the engine's failure code (too few keypoints, degenerate geometry, ...);
2. *central view*: no penalty area, goal area, goal or penalty arc among the observed classes (the
   circle, the half-way line and the side lines only): the position along the pitch rests on the
   circle alone;
3. *few keypoints*: fewer than 6 observed keypoints;
4. *an observed class is off*: a class the inputs hold is drawn more than 5 px from its annotation
   (the fit disagrees with its own evidence: an outlier kept, a bad vote, the lens);
5. *an unseen class is off*: only classes the inputs do not hold are off (the camera extrapolates:
   a line at the image border, a goal's posts).

Prints per set and class: the frames, their mean JaC@5, and the final score (FS = CR x JaC@5) the
set would reach were that class's frames perfect, and how many of them are off only by classes
the camera draws in the image that the annotation does not hold (``fp``: often a line grazing
the image border that the annotator left out); with ``--list N``, the N worst frames of each
class with the classes that are off (and for every class the classes most often off, left and
right counted together; ``far``: matched, a point beyond 5 px; ``fp``: drawn, not
annotated; ``fn``: annotated, not drawn).
"""

from __future__ import annotations

import argparse
import resource
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.inputs import observations_from_annotation, observations_from_predictions
from pnlviz.data import open_dataset, read_predictions
from pnlviz.metrics.soccernet import evaluate_frame

#: classes that fix the position along the pitch: any of them observed and the view is not "central"
ANCHORS = ("Big rect.", "Small rect.", "Goal ", "Circle left", "Circle right")
CLASSES = ("no camera", "central view", "few keypoints", "an observed class is off", "an unseen class is off")
MIN_KEYPOINTS = 6
THRESHOLD = 5.0


def frame_class(obs, result, score) -> tuple[str, list[str]]:
    """The class of failure of one frame (see the module docstring) and its classes that are off
    (``name: status``); ("", []) for a perfect frame."""
    if not result.ok:
        return f"no camera ({result.failure_code or 'failed'})", []
    matching = score.matching(THRESHOLD)
    off = {n: s for n, s in matching.class_status(THRESHOLD).items() if s != "tp"}
    if score.accuracy(THRESHOLD) >= 1.0 and not off:
        return "", []
    observed = set(obs.lines) | set(obs.circles)
    if matching.mirrored:  # the evaluator compared the mirrored labels: compare the mirrored names
        observed |= {_mirror_name(n) for n in observed}
    listed = [f"{n}: {s}" for n, s in sorted(off.items())]
    if not any(n.startswith(ANCHORS) for n in observed):
        return "central view", listed
    if obs.n_keypoints < MIN_KEYPOINTS:
        return "few keypoints", listed
    if any(n in observed for n in off):
        return "an observed class is off", listed
    return "an unseen class is off", listed


def _mirror_name(name: str) -> str:
    swap = {"left": "right", "right": "left", "top": "bottom", "bottom": "top"}
    return " ".join(swap.get(w, w) for w in name.split(" "))


def analyse(name: str, gt_annotation, observations: dict, list_n: int) -> None:
    params = CalibParams()
    rows = []
    for stem, obs in observations.items():
        result = calibrate(obs, params)
        score = evaluate_frame(result.camera if result.ok else None, gt_annotation(stem))
        acc = score.accuracy(THRESHOLD) if score.calibrated else None
        cls, off = frame_class(obs, result, score) if score.calibrated or not result.ok else ("no camera", [])
        rows.append((stem, acc, cls, off))
    n = len(rows)

    def fs(fixed: set[str]) -> float:
        accs = [1.0 if s in fixed else a for s, a, _, _ in rows]
        done = [a for a in accs if a is not None]
        return len(done) / n * float(np.mean(done)) if done else 0.0

    base = fs(set())
    groups: dict[str, list] = defaultdict(list)
    for r in rows:
        if r[2]:
            groups[r[2].split(" (")[0] if r[2].startswith("no camera") else r[2]].append(r)
    codes = defaultdict(int)
    for r in groups.get("no camera", []):
        codes[r[2][len("no camera ("):-1]] += 1
    perfect = n - sum(len(g) for g in groups.values())
    print(f"\n{name}: {n} frames, FS@5 {base:.4f}; {perfect} perfect at JaC@5")
    print("| class of failure | frames | of which only drawn, not annotated | mean JaC@5 | FS@5 were they perfect |")
    print("|---|---|---|---|---|")
    for cls in CLASSES:
        g = groups.get(cls, [])
        accs = [a for _, a, _, _ in g if a is not None]
        what = cls + (f" ({', '.join(f'{k} {v}' for k, v in sorted(codes.items()))})" if cls == "no camera" and g else "")
        mean = f"{np.mean(accs):.3f}" if accs else "-"
        drawn = sum(1 for _, _, _, off in g if off and all(o.endswith(": fp") for o in off))
        gain = fs({s for s, _, _, _ in g})
        print(f"| {what} | {len(g)} | {drawn} | {mean} | {gain:.4f} (+{gain - base:.4f}) |")
        often = Counter(o.split(":")[0].replace("left", "L/R").replace("right", "L/R").strip() for _, _, _, off in g
                        for o in off)
        if often:
            print("    most often off: " + ", ".join(f"{k} {v}" for k, v in often.most_common(5)))
        for stem, a, _, off in sorted(g, key=lambda r: (r[1] if r[1] is not None else -1.0))[:list_n]:
            print(f"    {stem}: JaC@5 {'-' if a is None else f'{a:.3f}'}  {'; '.join(off)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[2] / "shared")
    ap.add_argument("--list", type=int, default=0, metavar="N", help="list the N worst frames of each class")
    args = ap.parse_args()
    data = args.shared / "data"

    wc14 = data / "wc14_test_half"
    preds = read_predictions(wc14 / "detections_pnlcalib.zip")
    gt = open_dataset(wc14 / "annotations.zip")
    stems = sorted(preds, key=int)
    analyse("WC14 half, published PnLCalib detections", gt.annotation,
            {s: observations_from_predictions(preds[s], 960, 540) for s in stems}, args.list)

    sn22 = open_dataset(data / "sn22_test_subset" / "annotations.zip")
    analyse("SN22 subset, human annotations", sn22.annotation,
            {s: observations_from_annotation(sn22.annotation(s), 960, 540)[0] for s in sn22.stems}, args.list)
    print(f"\npeak memory (ru_maxrss): {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
