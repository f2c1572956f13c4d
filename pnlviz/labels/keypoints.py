"""Keypoint labels from SoccerNet line annotations (paper Sec. III-A, "Modeling the Soccer
Field": Keypoint Generation, Keypoint Disambiguation, Left-Right Disambiguation).

The pipeline, per frame, in pixels of the frame:

1. **Kp** - every straight class with >= 2 points gets a total-least-squares line (ground lines,
   goal posts and crossbars alike). The two lines of each catalogue ``line_line`` pair are
   intersected; the point is kept when it lies inside the image or at most ``kp_margin`` beyond
   it, *and* near an end of at least one of the two annotated segments (a real corner or T
   junction ends at least one of its segments; an intersection in the middle of both segments or
   far beyond them comes from a mislabelled line), *and* when the intersection is well
   conditioned (1 px of annotation noise moves it by at most ``max_noise_gain`` px; this drops
   nearly parallel lines and far extrapolations of short segments). A class that fails the
   segment-end test with one neighbour is "suspect" (not extended, not intersected with a circle);
   with two, it is dropped with all its points.
2. **Kpe** - the ``extended_line_line`` pairs of non-suspect classes, kept inside the image or up
   to ``kpe_beyond`` (50 %) of its size beyond it, and well conditioned as above.
3. **Kp1 / Kp2 candidates** - an ellipse is fitted (Halir-Flusser) to every circle class with
   >= 5 points spanning enough of the image; its intersections with the fitted line of the Kp1
   partner class give two candidates, the tangents from the external keypoint (a Kp label) two
   more. Which candidate is which keypoint is ambiguous (paper Fig. 2, bottom). A candidate is
   usable when it is inside the image, near the annotated arc and well conditioned (finite
   differences on the ellipse fit, ``max_conic_noise_gain``).
4. **Disambiguation** - with >= 4 ground points in Kp u Kpe (and a non-degenerate homography H
   that keeps the orientation; fitted with RANSAC to the Kp points first when they suffice, the
   Kpe points then checked against it, outliers rejected, see ``robust_base``): each Kp1 pair
   takes the assignment with the lower reprojection error under H, then H1 is refitted with Kp1,
   then the same for Kp2 (H2). Otherwise a set-wise
   grid search over every Kp1 and Kp2 assignment keeps the one with the lowest reprojection error
   of a homography fitted to Kp u Kpe u Kp1* u Kp2* (>= 4 points). Combinations whose
   homography flips the orientation (the mirror "bottom view", see :mod:`.fitting`) are not
   admissible; when two admissible ones tie, the pairs they disagree on are dropped.
   Nothing beyond Kp u Kpe is computed when neither works.
5. **Validation** - ground points farther than ``max_reproj_error`` from the projection of their
   world point by the final homography are rejected (worst first, refitting after each), then the
   cross-product orientation check drops points in triples whose image orientation disagrees
   with the world one.
6. **Kp3** - the final homography (fitted to >= ``min_points_kp3`` ground points) projects the 13
   additional points (and with ``kp3_all`` every catalogue ground point still missing); those in
   front of the camera, inside the image and not too far an extrapolation (``max_kp3_noise_gain``)
   are kept.

Only ground points (z = 0) take part in homographies; the goal-frame corners 12, 15, 16, 19
(z = -2.44) are Kp from the annotation only.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping

import numpy as np

from pnlviz.field.model import FieldModel
from pnlviz.field.names import CIRCLE_CLASSES, STRAIGHT_CLASSES, canonical_class_name
from pnlviz.geometry.conics import Conic, ConicError, fit_ellipse

from .catalogue import CandidatePair, Catalogue, get_catalogue
from .fitting import (
    conic_candidates_gain, fit_homography, fit_homography_robust, fit_line, homography_noise_gain, intersect,
    orientation_ok, orientation_outliers, project_h, reprojection_errors,
)
from .leftright import lr_decision, mirror_annotation
from .types import KeypointLabel, KeypointLabels, LabelParams, RejectedKeypoint

__all__ = ["annotation_to_pixels", "keypoints_from_annotation"]


def annotation_to_pixels(annotation: Mapping[str, np.ndarray], width: int | None,
                         height: int | None) -> dict[str, np.ndarray]:
    """Normalised SoccerNet annotation -> ``{canonical class: (N, 2) pixels}`` (x (W - 1), y (H - 1));
    unknown and ignored classes (``Goal unknown``, ``Line unknown``) are dropped. With ``width =
    height = None`` the points are taken as pixels already (only names are canonicalised)."""
    if width is None:
        scale = np.array([1.0, 1.0])
    else:
        assert height is not None, "a width without a height"
        scale = np.array([width - 1, height - 1], dtype=float)
    out: dict[str, np.ndarray] = {}
    for name, pts in annotation.items():
        canon = canonical_class_name(name)
        if canon is None or (canon not in STRAIGHT_CLASSES and canon not in CIRCLE_CLASSES):
            continue
        arr = np.asarray(pts, dtype=float).reshape(-1, 2)
        arr = arr[np.all(np.isfinite(arr), axis=1)]
        if len(arr):
            out[canon] = arr * scale
    return out


class _Line:
    """A fitted straight class: homogeneous line and the extent of its points along it."""

    def __init__(self, pts: np.ndarray, fit):
        self.line, self.centroid, self.dir = fit
        t = (pts - self.centroid) @ self.dir
        self.t0, self.t1 = float(t.min()), float(t.max())

    @property
    def length(self) -> float:
        return self.t1 - self.t0

    def position(self, p: np.ndarray) -> float:
        """Where ``p`` falls along the segment: 0 at one extreme point, 1 at the other."""
        return (float((p - self.centroid) @ self.dir) - self.t0) / max(self.length, 1e-9)

    def end_distance(self, p: np.ndarray) -> float:
        t = float((p - self.centroid) @ self.dir)
        return min(abs(t - self.t0), abs(t - self.t1))


class _Conic:
    def __init__(self, conic: Conic, pts: np.ndarray):
        self.conic = conic
        self.pts = pts


def intersection_noise_gain(a: _Line, b: _Line, x: np.ndarray) -> float:
    """Pixels the intersection ``x`` of two fitted lines moves per pixel of annotation noise,
    to first order, modelling each line as fixed by its two extreme points (independent unit
    noise): the line's offset at relative position ``s`` along it has standard deviation
    ``sqrt((1 - s)^2 + s^2)`` (1/sqrt(2) in the middle, growing linearly beyond the ends), and an
    offset ``d`` of one line moves the intersection by ``d / sin(angle)``."""
    sin = abs(float(a.dir[0] * b.dir[1] - a.dir[1] * b.dir[0]))
    if sin < 1e-12:
        return math.inf
    ga2 = sum(((1 - s) ** 2 + s ** 2) for s in [a.position(x)])
    gb2 = sum(((1 - s) ** 2 + s ** 2) for s in [b.position(x)])
    return math.sqrt(ga2 + gb2) / sin


def _sampson(conic: Conic, pts: np.ndarray) -> np.ndarray:
    X = np.hstack([pts, np.ones((len(pts), 1))])
    g = X @ conic.Q
    val = np.einsum("ni,ni->n", g, X)
    grad = 2 * np.linalg.norm(g[:, :2], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(val) / grad


class _Builder:
    def __init__(self, ann: dict[str, np.ndarray], width: int, height: int, params: LabelParams, cat: Catalogue):
        self.ann, self.W, self.H, self.p, self.cat = ann, width, height, params, cat
        self.diag = math.hypot(width, height)
        self.out = KeypointLabels(width=int(width), height=int(height), annotated_classes=frozenset(ann))
        self.lines: dict[str, _Line] = {}
        self.conics: dict[str, _Conic] = {}
        self.labels: dict[int, tuple[np.ndarray, str]] = {}  # id -> (xy, set)
        self.suspect: set[str] = set()

    # ---------------------------------------------------------------- helpers
    def visible(self, p: np.ndarray) -> bool:
        return bool(0 <= p[0] <= self.W - 1 and 0 <= p[1] <= self.H - 1)

    def reject(self, kid, kset, p, reason):
        x, y = (float(p[0]), float(p[1])) if p is not None else (math.nan, math.nan)
        self.out.rejected.append(RejectedKeypoint(kid, kset, x, y, reason))

    def world(self, ids) -> np.ndarray:
        return self.cat.world_xyz(ids)[:, :2]

    # ---------------------------------------------------------------- fits
    def fit_classes(self):
        for name in STRAIGHT_CLASSES:
            pts = self.ann.get(name)
            if pts is None or len(pts) < 2:
                continue
            f = fit_line(pts)
            if f is None or np.linalg.norm(np.ptp(pts, axis=0)) < self.p.min_line_length_diag * self.diag:
                self.out.notes.append(f"{name.strip()}: points too close together for a line")
                continue
            self.lines[name] = _Line(pts, f)
        p = self.p
        for name in CIRCLE_CLASSES:
            pts = self.ann.get(name)
            if pts is None:
                continue
            if len(pts) < p.min_conic_points:
                continue
            extent = float(np.linalg.norm(np.ptp(pts, axis=0)))
            if extent < p.min_conic_extent_diag * self.diag:
                self.out.notes.append(f"{name}: points span {extent:.1f} px, too little for an ellipse")
                continue
            try:
                conic = fit_ellipse(pts)
                conic.ellipse_params()  # raises for a non-ellipse
            except ConicError as exc:
                self.out.notes.append(f"{name}: {exc}")
                continue
            rms = float(np.sqrt(np.mean(_sampson(conic, pts) ** 2)))
            if not np.isfinite(rms) or rms > p.max_conic_residual_diag * self.diag:
                self.out.notes.append(f"{name}: ellipse residual {rms:.2f} px too large")
                continue
            self.conics[name] = _Conic(conic, pts)

    # ---------------------------------------------------------------- Kp, Kpe
    def line_line(self) -> None:
        p = self.p
        mx, my = p.kp_margin * self.W, p.kp_margin * self.H
        strikes: dict[str, int] = {}
        for pair in self.cat.kp:
            a, b = (self.lines.get(n) for n in pair.lines)
            if a is None or b is None:
                continue
            x = intersect(a.line, b.line)
            if x is None:
                self.reject(pair.id, "Kp", None, "lines parallel in the image")
                continue
            if not (-mx <= x[0] <= self.W - 1 + mx and -my <= x[1] <= self.H - 1 + my):
                continue  # outside the image: not a label, not an error
            tol = lambda ln: max(p.kp_end_tol_diag * self.diag, p.kp_end_tol_length * ln.length)  # noqa: E731
            if not (a.end_distance(x) <= tol(a) or b.end_distance(x) <= tol(b)):
                self.reject(pair.id, "Kp", x, "intersection far from the ends of both annotated segments")
                for n in pair.lines:
                    strikes[n] = strikes.get(n, 0) + 1
                continue
            gain = intersection_noise_gain(a, b, x)
            if gain > p.max_noise_gain:
                self.reject(pair.id, "Kp", x, f"ill-conditioned intersection (noise gain {gain:.1f})")
                continue
            self.labels[pair.id] = (x, "Kp")
        # A class whose intersection with a neighbour misses both segment ends may be mislabelled:
        # it is not extended (Kpe) nor intersected with a circle (Kp1). With two such neighbours
        # it most likely is (e.g. the big and small box lines swapped): it is dropped altogether.
        self.suspect = {name for name in strikes}
        for name, count in strikes.items():
            if count >= 2:
                self.out.notes.append(f"{name.strip()}: inconsistent with {count} neighbouring classes, not used")
                del self.lines[name]
                for pair in self.cat.kp:
                    if name in pair.lines and pair.id in self.labels:
                        xy, kset = self.labels.pop(pair.id)
                        self.reject(pair.id, kset, xy, f"{name.strip()} looks mislabelled")
        bx, by = p.kpe_beyond * self.W, p.kpe_beyond * self.H
        for pair in self.cat.kpe:
            a, b = (self.lines.get(n) for n in pair.lines)
            if a is None or b is None or self.suspect & set(pair.lines):
                continue
            x = intersect(a.line, b.line)
            if x is None:
                continue
            if -bx <= x[0] <= self.W - 1 + bx and -by <= x[1] <= self.H - 1 + by:
                gain = intersection_noise_gain(a, b, x)
                if gain > p.max_noise_gain:
                    self.reject(pair.id, "Kpe", x, f"ill-conditioned intersection (noise gain {gain:.1f})")
                    continue
                self.labels[pair.id] = (x, "Kpe")

    # ---------------------------------------------------------------- Kp1 / Kp2 candidates
    def candidates(self) -> list[tuple[CandidatePair, np.ndarray, np.ndarray]]:
        """``(pair, cands (2, 2), usable (2,))`` for every construction with two candidates."""
        out = []
        gap = self.p.max_conic_gap_diag * self.diag
        for pair in self.cat.kp1 + self.cat.kp2:
            c = self.conics.get(pair.circle)
            if c is None:
                continue
            line = external = None  # what the construction starts from: a line, or a keypoint's pixel
            if pair.kind == "Kp1":
                assert pair.line is not None  # a Kp1 construction names its line
                ln = self.lines.get(pair.line)
                if ln is None or pair.line in self.suspect:
                    continue
                line = ln.line
                cands = c.conic.intersect_line(line)
            else:
                assert pair.external is not None  # a Kp2 construction names its external keypoint
                ext = self.labels.get(pair.external)
                if ext is None or ext[1] != "Kp":
                    continue
                external = ext[0]
                cands = c.conic.tangent_points(external)
            if len(cands) != 2 or not np.all(np.isfinite(cands)) or np.linalg.norm(cands[0] - cands[1]) < 1e-6:
                self.out.notes.append(f"{pair.kind} on {pair.circle}: no pair of candidates")
                continue
            dist = np.min(np.linalg.norm(cands[:, None, :] - c.pts[None, :, :], axis=2), axis=1)
            usable = np.array([self.visible(q) for q in cands]) & (dist <= gap)
            if usable.any():
                gain = conic_candidates_gain(c.pts, cands, line=line, external=external)
                usable &= gain <= self.p.max_conic_noise_gain
            out.append((pair, cands, usable))
        return out

    @staticmethod
    def assigned(pair: CandidatePair, cands: np.ndarray, usable: np.ndarray, perm: tuple[int, int]
                 ) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Labelled points of one assignment: list of (id, world xy, image xy)."""
        pts = []
        for j in range(2):
            kid = pair.ids[j]
            if kid is not None and usable[perm[j]]:
                pts.append((kid, pair.world[j], cands[perm[j]]))
        return pts

    # ---------------------------------------------------------------- homographies
    def ground_points(self, sets=("Kp", "Kpe", "Kp1", "Kp2")):
        ids = [k for k, (_, s) in sorted(self.labels.items()) if s in sets and k in self.cat.ground_ids]
        img = np.array([self.labels[k][0] for k in ids], dtype=float).reshape(-1, 2)
        return ids, self.world(ids), img

    def fit_valid(self, world, img):
        H = fit_homography(world, img)
        if H is None or not orientation_ok(H, world):
            return None
        return H

    def disambiguate(self):
        H = self.robust_base()  # may reject Kp points, so before the tangents from them
        cands = self.candidates()
        if H is not None:
            self.out.disambiguation = "homography"
            for kind in ("Kp1", "Kp2"):
                for pair, cc, usable in (c for c in cands if c[0].kind == kind):
                    proj, w = project_h(H, pair.world)
                    errs = []
                    for perm in ((0, 1), (1, 0)):
                        e = np.linalg.norm(proj - cc[list(perm)], axis=1)
                        errs.append(float(np.sum(np.where(w > 0, e, 1e9))))
                    perm = (0, 1) if errs[0] <= errs[1] else (1, 0)
                    for kid, _, xy in self.assigned(pair, cc, usable, perm):
                        self.labels[kid] = (xy, kind)
                ids, world, img = self.ground_points()
                refit = self.fit_valid(world, img)  # H1, then H2
                H = H if refit is None else refit
            return H
        return self.grid_search(cands)

    def robust_base(self):
        """H from Kp u Kpe, robust to mislabelled lines. The line-line points (Kp) are the most
        trustworthy (both lines end there), so when they alone determine a homography it is
        fitted to them first (RANSAC when there are enough of them) and the extended-line points
        (Kpe, each a long extrapolation) are checked against it; otherwise RANSAC runs on
        Kp u Kpe. Outliers are rejected; the returned H is the least-squares fit of the rest."""
        thr = self.p.max_reproj_error_diag * self.diag
        for sets in (("Kp",), ("Kp", "Kpe")):
            ids, world, img = self.ground_points(sets)
            if len(ids) < 4:
                continue
            H, inl = fit_homography_robust(world, img, thr)
            if H is None or not orientation_ok(H, world[inl]):
                continue
            for kid, ok, e in zip(ids, inl, reprojection_errors(H, world, img)):
                if not ok:
                    xy, kset = self.labels.pop(kid)
                    self.reject(kid, kset, xy, f"outlier of the homography of the other points ({e:.1f} px)")
            if sets == ("Kp",):
                ids, world, img = self.ground_points(("Kpe",))
                for kid, e in zip(ids, reprojection_errors(H, world, img)):
                    if e > thr:
                        xy, kset = self.labels.pop(kid)
                        self.reject(kid, kset, xy, f"off the homography of the Kp points ({e:.1f} px)")
                refit = self.fit_valid(*self.ground_points(("Kp", "Kpe"))[1:])
                H = H if refit is None else refit
            return H
        return None

    def grid_search(self, cands: list[tuple[CandidatePair, np.ndarray, np.ndarray]]) -> np.ndarray | None:
        if not cands:
            return None
        base_ids, base_world, base_img = self.ground_points(("Kp", "Kpe"))
        n_comb = 2 ** len(cands)
        if n_comb > self.p.max_grid_combinations:
            self.out.notes.append(f"grid search skipped: {n_comb} combinations")
            return None
        results = []
        for perms in itertools.product(((0, 1), (1, 0)), repeat=len(cands)):
            extra = [pt for (pair, cc, us), perm in zip(cands, perms) for pt in self.assigned(pair, cc, us, perm)]
            if len(base_ids) + len(extra) < 4:
                continue
            world = np.vstack([base_world] + [e[1][None] for e in extra]) if extra else base_world
            img = np.vstack([base_img] + [e[2][None] for e in extra]) if extra else base_img
            H = self.fit_valid(world, img)
            if H is None:
                continue
            err = float(np.sqrt(np.mean(reprojection_errors(H, world, img) ** 2)))
            results.append((err, perms, H, extra))
        if not results:
            return None
        results.sort(key=lambda r: r[0])
        best_err, best_perms, H, extra = results[0]
        self.out.disambiguation = "grid"
        drop: set[int] = set()
        tie = 0.5 + 0.1 * best_err
        for err, perms, _, _ in results[1:]:
            if err > best_err + tie:
                break
            for i, (pa, pb) in enumerate(zip(best_perms, perms)):
                ka = {k: tuple(xy) for k, _, xy in self.assigned(*cands[i], pa)}
                kb = {k: tuple(xy) for k, _, xy in self.assigned(*cands[i], pb)}
                if ka != kb:
                    drop.add(i)
        for i, ((pair, cc, us), perm) in enumerate(zip(cands, best_perms)):
            for kid, _, xy in self.assigned(pair, cc, us, perm):
                if i in drop:
                    self.reject(kid, pair.kind, xy, "ambiguous: another assignment fits as well")
                else:
                    self.labels[kid] = (xy, pair.kind)
        if drop:
            ids, world, img = self.ground_points()
            H = self.fit_valid(world, img)
        return H

    # ---------------------------------------------------------------- validation
    def validate(self, H):
        thr = self.p.max_reproj_error_diag * self.diag
        while H is not None:
            ids, world, img = self.ground_points()
            err = reprojection_errors(H, world, img)
            worst = int(np.argmax(err)) if len(err) else -1
            if worst < 0 or err[worst] <= thr:
                break
            kid = ids[worst]
            xy, kset = self.labels.pop(kid)
            reason = "behind the camera" if not np.isfinite(err[worst]) else \
                f"reprojection error {err[worst]:.1f} px > {thr:.1f} px"
            self.reject(kid, kset, xy, reason)
            H = self.fit_valid(*self.ground_points()[1:])
        if self.p.orientation_check:  # needs no homography: also checks Kp u Kpe alone
            ids, world, img = self.ground_points()
            bad = orientation_outliers(world, img)
            for i in bad:
                xy, kset = self.labels.pop(ids[i])
                self.reject(ids[i], kset, xy, "cross-product orientation disagrees with the world")
            if bad and H is not None:
                H = self.fit_valid(*self.ground_points()[1:])
        return H

    def complete(self, H):
        ids, world, img = self.ground_points()
        if H is None or len(ids) < self.p.min_points_kp3:
            return
        targets = list(self.cat.kp3)
        if self.p.kp3_all:
            targets += [k for k in sorted(self.cat.ground_ids) if k not in self.cat.kp3]
        targets = [k for k in targets if k not in self.labels]
        if not targets:
            return
        txy = self.cat.world_xyz(targets, pnlcalib=self.p.pnlcalib_positions)[:, :2]
        xy, w = project_h(H, txy)
        keep = (w > 0) & np.all(np.isfinite(xy), axis=1) & np.array([self.visible(q) for q in xy], bool)
        if not keep.any():
            return
        gain = np.full(len(targets), np.inf)
        gain[keep] = homography_noise_gain(world, img, txy[keep])
        for kid, q, k, g in zip(targets, xy, keep, gain):
            if not k:
                continue
            if g > self.p.max_kp3_noise_gain:
                self.reject(kid, "Kp3", q, f"homography extrapolates too far (noise gain {g:.1f})")
                continue
            self.labels[kid] = (q, "Kp3")

    def finish(self, H):
        out = self.out
        out.homography = None if H is None else H / np.linalg.norm(H)
        for kid in sorted(self.labels):
            xy, kset = self.labels[kid]
            out.keypoints[kid] = KeypointLabel(kid, float(xy[0]), float(xy[1]), self.visible(xy), kset)
        if H is not None:
            ids, world, img = self.ground_points(("Kp", "Kpe", "Kp1", "Kp2"))  # Kp3 are H's own
            for kid, e in zip(ids, reprojection_errors(H, world, img)):
                out.reprojection_errors[kid] = float(e)
        return out


def keypoints_from_annotation(annotation: Mapping[str, np.ndarray], width: int, height: int,
                              params: LabelParams = LabelParams(), *, model: FieldModel | None = None,
                              pixels: bool = False) -> KeypointLabels:
    """Keypoint labels (every set of the paper, pixels) of one frame from its line annotation.

    ``annotation``: ``{class: (N, 2)}`` normalised SoccerNet coordinates as read by
    :func:`pnlviz.data.open_dataset` (``x_px = x (W - 1)``), or pixels with ``pixels=True``.
    Never raises on odd input: what cannot be computed is skipped and explained in ``notes`` /
    ``rejected``.
    """
    width, height = int(width), int(height)
    ann = annotation_to_pixels(annotation, None, None) if pixels else annotation_to_pixels(annotation, width, height)
    cat = get_catalogue(model)
    labels = _run(ann, width, height, params, cat)
    if params.lr_disambiguation:
        ground = [k for k in labels.ids(visible_only=True) if k in cat.ground_ids]
        decision = lr_decision(labels.homography, labels.xy(ground).mean(axis=0) if ground else None)
        if decision.mirror:
            labels = _run(mirror_annotation(ann), width, height, params, cat)
            labels.mirrored = True
        labels.notes.insert(0, f"left-right: {decision.reason}")
    return labels


def _run(ann: dict[str, np.ndarray], width: int, height: int, params: LabelParams, cat: Catalogue) -> KeypointLabels:
    b = _Builder(ann, width, height, params, cat)
    b.fit_classes()
    b.line_line()
    H = b.disambiguate()
    H = b.validate(H)
    b.complete(H)
    return b.finish(H)
