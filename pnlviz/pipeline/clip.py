"""A clip of a dataset under its shot model, for every caller (the app, export, scripts): the
clip's :class:`pnlviz.calib.clip.ClipSolver` built from a :class:`pnlviz.pipeline.reader.FrameReader`
(each frame's own observations, its keypoint edits from the edits folder, the cuts changed by
hand), and a whole shot reviewed at once (:func:`accept_shot`): every frame of it records a review
snapshot of what the shot model shows (the shot's camera, the labels with their provenance:
``detection`` / ``annotation``, ``hand``, ``shot``), which is what an export writes.

The cuts a hand added or removed are kept in the edits folder, beside the frames' records:
``<edits>/clips/<clip>.json``, ``{"cuts": {"added": [frame index, ...], "removed": [...]}}``
(a cut before the clip's t-th frame, 0-based, is named by t).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from pnlviz.calib.clip import ClipSolver
from pnlviz.calib.cuts import CutEdits
from pnlviz.calib.frame import calib_params, detection_settings_apply, observations_for
from pnlviz.calib.looks import shot_observations
from pnlviz.calib.observations import Observations
from pnlviz.calib.shot import TemporalParams
from pnlviz.calib.temporal import image_changes
from pnlviz.data import atomic_write_text
from pnlviz.data.errors import DataError
from pnlviz.data.layout import video_clips
from pnlviz.data.state_files import read_state_json
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.pipeline.reader import FrameReader, Settings
from pnlviz.pipeline.snapshot import provenance, review_snapshot

__all__ = ["accept_shot", "clip_changes", "clip_solver", "dataset_clips", "read_cuts", "set_cut", "shot_snapshot"]



def dataset_clips(stems: Sequence[str]) -> dict[str, list[str]]:
    """``{clip: [stems in frame order]}`` of a dataset's clips (the one rule:
    :func:`pnlviz.data.layout.video_clips`)."""
    return video_clips(stems)


def _cuts_path(reader: FrameReader, clip: str) -> Path:
    return reader.edits_folder.layout.cuts(clip)


def _cuts_of(obj) -> CutEdits:
    if not isinstance(obj, dict) or set(obj) != {"cuts"}:
        raise ValueError(f'expected {{"cuts": {{"added": [...], "removed": [...]}}}}, got {str(obj)[:80]!r}')
    return CutEdits.from_json(obj["cuts"])


def read_cuts(reader: FrameReader, clip: str) -> CutEdits:
    """The cuts a hand changed in ``clip`` (none when nothing was saved). A file that is not
    what :func:`set_cut` writes (damaged, a FIFO, ``/dev/zero``) is set aside with a warning
    (:mod:`pnlviz.data.state_files`), never read as "no cuts" and then written over."""
    cuts = read_state_json(_cuts_path(reader, clip), reader.edits_folder.warnings, check=_cuts_of)
    return cuts if cuts is not None else CutEdits()


def set_cut(reader: FrameReader, solver: ClipSolver, clip: str, t: int, cut: bool) -> None:
    """A cut before frame ``t`` of ``clip`` added or removed by hand: saved, and the solver's
    shots changed (the shots it touches solved again)."""
    solver.set_cut(t, cut)
    path = _cuts_path(reader, clip)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps({"cuts": solver.cuts.to_json()}))


def clip_changes(reader: FrameReader, stems: Sequence[str]) -> list[float | None] | None:
    """The image change from each frame of a clip to the next (None when no frame has an image)."""
    def images():
        for s in stems:
            try:
                yield reader.ds.image(s) if reader.ds.frame(s).has_image else None
            except DataError:
                yield None

    if not any(reader.ds.frame(s).has_image for s in stems):
        return None
    return image_changes(images())


def clip_solver(reader: FrameReader, clip: str, stems: Sequence[str], settings: Settings | None = None, *,
                changes: Sequence[float | None] | None = None, model: FieldModel | None = None,
                cameras: Sequence | None = None) -> ClipSolver:
    """The clip ``stems`` (in frame order) under its shot model: each frame's own observations
    under ``settings`` (default: the reader's), its keypoint edits and the clip's hand cuts from
    the edits folder, ``changes`` (:func:`clip_changes`) to find the cuts; ``cameras``: the
    frames' own cameras under ``settings`` with their edits, when known (else calibrated here)."""
    model = model or load_field_model()
    settings = settings or reader.default_settings()
    fs = reader.frame_settings(settings)
    cameras = None if cameras is None else list(cameras)
    base: list[Observations | None] = []
    origins: list[str | dict[int, str]] = []
    edits: dict[int, dict] = {}
    looked: set[int] = set()
    origin0: str | None = None
    size: tuple[int, int] | None = None
    for t, stem in enumerate(stems):
        read = reader.read(stem)
        if read.inputs is None:
            base.append(None)
            origins.append("detection")
            continue
        size = size or (int(read.inputs.size[0]), int(read.inputs.size[1]))
        obs, origin, second = shot_observations(replace(read.inputs, keypoint_edits=None), fs, model)
        if second:  # its first reading gave no camera: that is why the frame holds a second look
            looked.add(t)
            if cameras is not None:
                cameras[t] = None
        origin0 = origin0 or origin
        base.append(obs)
        # what each point is called: the rule of a frame's own review snapshot (annotation wins)
        origins.append(dict(zip(obs.kp_ids.tolist(), provenance(obs, origin, read.inputs.annotation, None, model)))
                       if obs is not None else "detection")
        if read.inputs.keypoint_edits:
            edits[t] = dict(read.inputs.keypoint_edits)
    cp = calib_params(fs, origin0)
    frame_size = size or (int(reader.size[0]), int(reader.size[1]))
    return ClipSolver(base, frame_size, TemporalParams(fit_k1=cp.refine_k1), cp, changes=changes,
                      cuts=read_cuts(reader, clip), origins=origins, model=model, keypoint_edits=edits,
                      cameras=cameras, looked=frozenset(looked))


def shot_snapshot(reader: FrameReader, solver: ClipSolver, clip: str, stems: Sequence[str], t: int,
                  settings: Settings | None = None) -> dict:
    """The review snapshot of frame ``t`` of the clip as its shot model shows it (format:
    :mod:`pnlviz.data.snapshot`): the shot's camera and the frame's labels with provenance."""
    settings = settings or reader.default_settings()
    fs = reader.frame_settings(settings)
    stem = stems[t]
    record = reader.edits.get(stem) if reader.edits is not None else {}
    read = reader.read(stem)
    origin = None
    if read.inputs is not None:
        origin = observations_for(replace(read.inputs, keypoint_edits=None), fs.source, solver.field_model)[1]
    dets = reader.detections(stem) if origin in ("detections", "both") else None
    k = solver.shot_of(t)
    shot = solver.shots[k]
    return review_snapshot(record, solver.labels(t), solver.camera(t), "the shot has no camera here",
                           settings=settings, detection_settings=detection_settings_apply(origin, fs),
                           size=solver.size, detections=dets,
                           shot={"clip": clip, "shot": k, "first": stems[shot.start], "last": stems[shot.stop - 1]})


def _accept(record: dict) -> None:
    """The review of a frame of an accepted shot: accepted, unless corrected by hand."""
    if record.get("review") != "corrected":
        record["review"] = "accepted"


def accept_shot(reader: FrameReader, solver: ClipSolver, clip: str, stems: Sequence[str], k: int,
                settings: Settings | None = None, write: Callable[..., object] | None = None) -> list[str]:
    """Review shot ``k`` of the clip at once: every frame of it accepted (a frame corrected by hand
    stays "corrected"), with the snapshot of what the shot model shows (one undo step per frame).
    ``write(stem, change, corrected=False, snapshot=...)``: the door the app's edits go through
    (:meth:`pnlviz.app.state.AppState.write`, which tells every tab); by default the edits folder
    is written directly. Returns the stems reviewed."""
    folder = reader.edits_folder

    def direct(stem: str, change: Callable[[dict], None], *, corrected: bool,
               snapshot: Callable[[dict], dict]) -> None:
        with folder.lock(stem):  # the snapshot and the review it goes with are one
            folder.act(stem, change, corrected=corrected)
            folder.update(stem, snapshot=snapshot(folder.get(stem)))

    write = write or direct
    done = []
    for t in solver.shots[k]:
        def snapshot(record: dict, t: int = t) -> dict:  # taken under the frame's lock, with the review
            return shot_snapshot(reader, solver, clip, stems, t, settings)

        write(stems[t], _accept, corrected=False, snapshot=snapshot)  # the tabs are told after the lock
        done.append(stems[t])
    return done
