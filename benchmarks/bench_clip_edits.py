"""How many hand edits a clip needs: correcting every frame on its own against correcting the shot.

    python benchmarks/bench_clip_edits.py --seed S [--clips 2] [--frames 60] [--target 0.95] [--limit 300]

Renders ``--clips`` synthetic clips (``pnlviz synth --clip``: pan-tilt-zoom shots with a cut about
every 60 frames; clip seeds ``10 S``, ``10 S + 1``, ...; 960x540), detects them with the default
(light) model on one thread, calibrates every frame, and then corrects each clip as an annotator
would, twice:

* **per frame**: an edit recalibrates its frame alone (the frame's detections with its edits, the
  pins weighing more: :func:`pnlviz.calib.frame.calibrate_frame`);
* **shot model**: an edit is a pinned constraint of its shot's solve, and every frame of the shot
  gets its new camera (:class:`pnlviz.calib.clip.ClipSolver`, solved again from its previous
  solution).

The simulated annotator, at each step: among the frames whose camera is visibly off (JaC@5
against the frame's annotation below 1, or no camera) takes the one the app ranks worst (no
camera first, then the largest median residual of the frame's observations under its camera);
there, moves the keypoint farthest from its true position to the truth when it is more than
``--move-px`` off (hides it when its true position is not in view), else places the missing
keypoint in view whose projection by the current camera is farthest from the truth (without a
camera: the one farthest from the frame's other points). A frame with nothing left to do is
passed over. The pitch is the same turned half a turn: where a frame's points follow that
labelling (the detector took left for right), so does the annotator (FS@5 accepts either
labelling, as the SoccerNet evaluator does). It stops when the clip's FS@5 (completeness x mean
JaC@5, the SoccerNet metric against the annotations made from the true cameras) reaches
``--target``, or after ``--limit`` edits. Prints, summed over the clips::

    edits to FS@5 0.95: per-frame N1, shot model N2 (frames F, shots S)

(S: the shots the shot model starts with: cuts where the images change, as the app finds them;
a clip that did not reach the target counts its limit, marked ``+``) and the time of the shot
re-solves after an edit.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def render_and_detect(seed: int, frames: int):
    """One synthetic clip: its plan (true cameras), annotations, detections, image changes."""
    from pnlviz.calib.temporal import image_change
    from pnlviz.data.annotations import parse_annotation
    from pnlviz.detect.run import Detector
    from pnlviz.synth.clip import clip_frame, plan_clip

    plan = plan_clip(seed, frames)
    det = Detector.from_weights(None, None)
    preds, anns, changes, prev = [], [], [], None
    for t in range(frames):
        f = clip_frame(plan, t)
        if prev is not None:
            changes.append(image_change(prev, f["image"]))
        prev = f["image"]
        preds.append(det.detect([f["image"]])[0])
        anns.append(parse_annotation(f["annotation"]))
    return plan, anns, preds, changes, dict(det.calibration)


class PerFrame:
    """Every frame corrected on its own."""

    def __init__(self, preds, settings, size, model):
        from pnlviz.calib.frame import FrameInputs, calibrate_frame

        self.preds, self.settings, self.size, self.model = preds, settings, size, model
        self.edits: list[dict] = [{} for _ in preds]
        self._calibrate = lambda t: calibrate_frame(FrameInputs(size, detections=preds[t],
                                                                keypoint_edits=self.edits[t] or None), settings, model)
        self.frames = [self._calibrate(t) for t in range(len(preds))]

    def camera(self, t):
        fc = self.frames[t]
        return fc.result.camera if fc.ok else None

    def observations(self, t):
        return self.frames[t].observations

    def error(self, t) -> float:
        fc = self.frames[t]
        if not fc.ok:
            return np.inf
        r = list(fc.result.point_residuals.values()) + list(fc.result.line_residuals.values())
        return float(np.median(r)) if r else 0.0

    def edits_of(self, t) -> dict:
        return self.edits[t]

    def edit(self, t, kid, xy) -> list[int]:
        self.edits[t][str(kid)] = None if xy is None else [float(xy[0]), float(xy[1])]
        self.frames[t] = self._calibrate(t)
        return [t]


class ShotModel:
    """Edits drive the shot's solve (:class:`pnlviz.calib.clip.ClipSolver`)."""

    def __init__(self, start: PerFrame, changes, params, calib_params, size, model):
        from pnlviz.calib.clip import ClipSolver

        T = len(start.frames)
        self.solver = ClipSolver([start.observations(t) for t in range(T)], size, params, calib_params,
                                 cameras=[start.camera(t) for t in range(T)], changes=changes, model=model)
        self.seconds: list[tuple[int, float]] = []

    def camera(self, t):
        return self.solver.camera(t)

    def observations(self, t):
        return self.solver.frame_observations(t)

    def error(self, t) -> float:
        return self.solver.frame_error(t)

    def edits_of(self, t) -> dict:
        return self.solver.edits.get(t, {})

    def edit(self, t, kid, xy) -> list[int]:
        k = self.solver.set_keypoint(t, kid, xy)
        self.seconds.append((len(self.solver.shots[k]), self.solver.solve_seconds(k)))
        return list(self.solver.shots[k])


def _truth_points(cam, model):
    """Every catalogue keypoint in view of the true camera: {id: (x, y)}."""
    ids = np.array(model.keypoint_ids)
    X = model.keypoint_xyz(ids)
    uv, z = cam.project(X)
    flat, _ = cam.project(X, distort=False)
    ok = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    ok &= (np.abs(flat[:, 0] - cam.cx) < cam.width) & (np.abs(flat[:, 1] - cam.cy) < cam.height)
    return {int(i): uv[j] for j, i in enumerate(ids) if ok[j]}


def half_turn(cam):
    """The camera that sees the pitch turned half a turn about its centre: the same picture with
    the other labelling (left for right, near for far)."""
    from dataclasses import replace

    D = np.diag([-1.0, -1.0, 1.0])
    return replace(cam, R=cam.R @ D, C=D @ cam.C)


def labelling(mode, t, truth):
    """The true camera in the labelling frame ``t``'s points follow: the pitch is the same turned
    half a turn, a detector may label a clip so (and FS@5 accepts either labelling, as the
    SoccerNet evaluator does); the annotator corrects within the labelling the frame has."""
    obs = mode.observations(t)
    if obs is None or not obs.n_keypoints:
        cam = mode.camera(t)
        if cam is None:
            return truth
        twin = half_turn(truth)
        return twin if np.linalg.norm(cam.C - twin.C) < np.linalg.norm(cam.C - truth.C) else truth

    def fit(cam):
        uv, z = cam.project(obs.kp_xyz)
        d = np.where(z > 0, np.hypot(*(uv - obs.kp_xy).T), np.inf)
        return float(np.median(d))

    twin = half_turn(truth)
    return twin if fit(twin) < fit(truth) else truth


def next_edit(mode, t, truth, model, move_px: float):
    """The annotator's edit on frame ``t``: (id, true position, or None to hide a point that is not
    in view), or None when nothing is left to do."""
    obs = mode.observations(t)
    in_view = _truth_points(truth, model)
    seen = {}
    if obs is not None:
        for i, kid in enumerate(obs.kp_ids.tolist()):
            if not obs.pins[i]:
                seen[kid] = float(np.hypot(*(in_view[kid] - obs.kp_xy[i]))) if kid in in_view else np.inf
    if seen:
        kid = max(seen, key=lambda k: seen[k])
        if seen[kid] > move_px:
            return kid, in_view.get(kid)
    placed = set(obs.kp_ids.tolist()) if obs is not None else set()
    hidden = {int(k) for k, v in (mode.edits_of(t) or {}).items() if v is None}
    missing = {k: v for k, v in in_view.items() if k not in placed and k not in hidden}
    if not missing:
        return None
    cam = mode.camera(t)
    if cam is not None:
        ids = np.array(sorted(missing))
        uv, z = cam.project(model.keypoint_xyz(ids))
        score = {int(k): (float(np.hypot(*(uv[j] - missing[int(k)]))) if z[j] > 0 and np.all(np.isfinite(uv[j]))
                          else np.inf) for j, k in enumerate(ids)}
    else:
        others = obs.kp_xy if obs is not None and obs.n_keypoints else np.zeros((0, 2))
        score = {k: (float(np.min(np.hypot(*(others - v).T))) if len(others) else 0.0) for k, v in missing.items()}
    kid = max(score, key=lambda k: (score[k], -k))
    return kid, missing[kid]


def correct(mode, truths, anns, model, target: float, limit: int, move_px: float) -> tuple[int, float, float]:
    """Edits until the clip's FS@5 reaches ``target`` (or ``limit``): (edits, FS@5 before, after)."""
    from pnlviz.metrics.soccernet import evaluate_frame

    T = len(truths)

    def accuracy(t):
        cam = mode.camera(t)
        return None if cam is None else evaluate_frame(cam.scaled(960, 540), anns[t]).accuracy(5)

    acc = [accuracy(t) for t in range(T)]

    def fs():
        calibrated = [a for a in acc if a is not None]
        return len(calibrated) / T * float(np.mean(calibrated)) if calibrated else 0.0

    first, done, edits = fs(), set(), 0
    while fs() < target and edits < limit:
        wrong = [t for t in range(T) if t not in done and (acc[t] is None or acc[t] < 1.0)]
        if not wrong:
            break
        t = max(wrong, key=lambda u: (mode.error(u), -u))
        step = next_edit(mode, t, labelling(mode, t, truths[t]), model, move_px)
        if step is None:
            done.add(t)
            continue
        for u in mode.edit(t, *step):
            acc[u] = accuracy(u)
        edits += 1
    return edits, first, fs()


def run_clip(seed: int, frames: int, args) -> dict:
    from pnlviz.calib.frame import FrameSettings, calib_params
    from pnlviz.calib.shot import TemporalParams
    from pnlviz.field import load_field_model

    model = load_field_model()
    t0 = time.perf_counter()
    plan, anns, preds, changes, det_settings = render_and_detect(seed, frames)
    prep = time.perf_counter() - t0
    size = tuple(plan.size)
    settings = FrameSettings(source="detections", detection_settings=det_settings)
    cp = calib_params(settings, "detections")
    params = TemporalParams(fit_k1=cp.refine_k1)
    out = {"frames": frames, "prep_s": prep}
    per = PerFrame(preds, settings, size, model)
    shot = ShotModel(per, changes, params, cp, size, model)  # from the per-frame cameras before any edit
    out["shots"] = len(shot.solver.shots)
    n, a, b = correct(per, plan.cameras, anns, model, args.target, args.limit, args.move_px)
    out["per_frame"] = (n, a, b)
    n, a, b = correct(shot, plan.cameras, anns, model, args.target, args.limit, args.move_px)
    out["shot"] = (n, a, b)
    out["solve_s"] = shot.seconds
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--clips", type=int, default=2)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--target", type=float, default=0.95)
    ap.add_argument("--limit", type=int, default=300)
    ap.add_argument("--move-px", type=float, default=3.0, help="a keypoint this far off is moved (default 3 px)")
    args = ap.parse_args(argv)
    import cv2
    import torch

    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    runs = []
    for k in range(args.clips):
        seed = 10 * args.seed + k
        r = run_clip(seed, args.frames, args)
        runs.append(r)
        (n1, a1, b1), (n2, a2, b2) = r["per_frame"], r["shot"]
        print(f"clip {seed}: {r['frames']} frames, {r['shots']} shots; per-frame {n1} edits (FS@5 {a1:.3f} -> "
              f"{b1:.3f}), shot model {n2} edits ({a2:.3f} -> {b2:.3f}); render+detect {r['prep_s']:.0f} s")

    def total(key):
        n = sum(r[key][0] for r in runs)
        short = any(r[key][2] < args.target for r in runs)
        return f"{n}{'+' if short else ''}"

    solves = [s for r in runs for _, s in r["solve_s"]]
    longest = max((n for r in runs for n, _ in r["solve_s"]), default=0)
    print(f"edits to FS@5 {args.target:g}: per-frame {total('per_frame')}, shot model {total('shot')} "
          f"(frames {sum(r['frames'] for r in runs)}, shots {sum(r['shots'] for r in runs)})")
    if solves:
        print(f"shot re-solve after an edit: median {1e3 * np.median(solves):.0f} ms, max {1e3 * max(solves):.0f} ms "
              f"(longest shot {longest} frames)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
