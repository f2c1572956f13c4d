"""Export corrected training labels of a dataset and its edits folder: what ``pnlviz export``
writes (locally or on a cluster's workers) and the app's export button downloads, from a
:class:`pnlviz.pipeline.reader.FrameReader` and calibration settings.

Layout (a folder or a zip):

* ``annotations/<stem>.json``: SoccerNet line annotation, with the corrected line points;
* ``keypoints/<stem>.json``: keypoint labels, ``{"image_size": [W, H], "reviewed": bool, "review":
  status, "keypoints": {"id": {"x", "y", "visible", "occluded", "set", "provenance", "residual", "flagged",
  "slip"}}}``
  in pixels, corrected keypoints included (hidden ones left out); ``provenance``: annotation,
  detection, hand, or shot (a frame reviewed with its clip's shot model, :mod:`pnlviz.pipeline.clip`:
  a point placed by hand on another frame of the shot, carried here through the shot's cameras);
  ``residual``: px to the frame's exported camera; ``flagged``: beyond the outlier gate
  (:mod:`pnlviz.pipeline.snapshot`), not ground truth; ``slip``: placed by hand farther than the
  gate from where the rest of the frame puts it (kept as placed; the manifest's ``"slips"`` gives
  the distances, null where the rest puts it off the camera);
* ``cameras/camera_<stem>.json``: the calibrated camera at 960x540 (SoccerNet format);
* ``homographies.json``: ``{stem: 3x3}``, each calibrated frame's homography from the ground plane
  (X, Y, 1) in metres (SoccerNet world frame) to the frame's own pixels, without lens distortion
  (the camera file has it); its inverse maps pixels to the pitch. The same matrix is in the
  frame's keypoints file (``"homography"``, null without a camera);
* ``coco_keypoints.json``: COCO keypoints, one "pitch" instance per frame with the 73 keypoints
  (v = 2 inside the image, 1 labelled outside it or occluded, 0 absent or flagged by the gate);
* ``manifest.json``: what each exported frame carries and what was changed (names, not paths:
  the export does not say where the server's files live), its ``"occluded"`` keypoints and the
  annotator's ``"note"``.

A frame of a dataset in splits (stem ``<split>/<stem>``) keeps its split in every name:
``annotations/valid/00042.json``, ``cameras/valid/camera_00042.json``.

Only accepted and corrected frames are exported unless ``include_all``; a reviewed frame exports
what its review recorded (its snapshot), whatever the reader's detections, and unreviewed ones
(``include_all``) are calibrated from the reader's inputs and marked ``"reviewed": false``. A frame whose files
cannot be read is listed in the manifest with its error and gets no label files (an empty label
file would say "no keypoints", which is not what is known); so does an unreviewed frame with
nothing to export (no annotation, no detections, no point placed by hand: ``"empty"`` says so),
while a reviewed frame without labels (an annotator confirmed there is none) is exported empty.
"""

from __future__ import annotations

import json
import time
import zipfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pnlviz.data import atomic_write_bytes
from pnlviz.data.cameras import camera_member_name
from pnlviz.data.annotations import annotation_to_json
from pnlviz.data.jsonio import dumps
from pnlviz.data.zipwriter import ZipStream
from pnlviz.data.errors import DataError
from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.pipeline.reader import FrameReader, Settings
from pnlviz.pipeline.snapshot import GATE_PX, REVIEWED, FrameLabels, gate, inside, reviewed_labels, view_labels
from pnlviz.pipeline.view import FrameView, frame_view

N_KEYPOINTS = 73


@dataclass
class FrameExport:
    """One frame's part of an export: its manifest entry, its label files and its COCO records
    (None when it exports no labels). What a cluster worker sends back for the frame."""

    stem: str
    entry: dict
    files: dict[str, bytes] = field(default_factory=dict)
    coco_image: dict | None = None
    coco_annotation: dict | None = None
    homography: list[list[float]] | None = None
    camera: dict | None = None  # the exported camera (SoccerNet dict at 960x540), None without one


def export_stems(reader: FrameReader, include_all: bool = False) -> list[str]:
    """The frames an export holds, in dataset order: the accepted and corrected ones, or all."""
    if include_all:
        return list(reader.stems)
    return [s for s in reader.stems if reader.edits_folder.review(s) in REVIEWED]


def edits_entry(reader: FrameReader, stem: str) -> dict:
    """What the manifest says of a frame's edits: its review status and what was changed."""
    rec = reader.edits_folder.get(stem)
    return {"review": rec.get("review"), "annotation_edited": rec.get("annotation") is not None,
            "keypoints_edited": sorted(int(k) for k in (rec.get("keypoints") or {}))}


def failed_frame(reader: FrameReader, stem: str, message: str) -> FrameExport:
    """The export of a frame whose computation failed elsewhere (a cluster task): what the edits
    say of it, the error, no labels."""
    return FrameExport(stem, {**edits_entry(reader, stem), "calibrated": False, "error": f"{stem}: {message}",
                              "exported": False})


def _frame_labels(reader: FrameReader, stem: str, record: dict, settings: Settings | None, model: FieldModel,
                  view: FrameView | None) -> FrameLabels:
    """What the frame exports: a reviewed frame what its review recorded, another its view."""
    if record.get("review") in REVIEWED:
        return reviewed_labels(reader, stem, record, model)
    view = view or frame_view(reader, stem, settings or reader.default_settings(), model)
    if view.annotation is None and view.observations is None and view.error:  # unreadable
        return FrameLabels(view.size, {}, None, view.error, "unreviewed", error=view.error)
    return view_labels(view, record, model)


def _entry_extras(entry: dict, record: Mapping, fl: FrameLabels) -> tuple[Mapping, set[int]]:
    """What the manifest entry says besides the labels (the shot a frame was reviewed with, its
    slips, its occluded points, its note); returns the slips and the occluded ids."""
    snap = record.get("snapshot") or {}
    if snap.get("shot") is not None and fl.basis == "snapshot":
        entry["shot"] = snap["shot"]  # reviewed with its shot: the camera is the shot model's
    slips = (snap.get("slips") or {}) if fl.basis == "snapshot" else {}
    if slips:  # hand points the rest of the frame disagreed with when it was reviewed: kept, listed
        entry["slips"] = dict(slips)
    occluded = set(record.get("occluded") or ())
    if occluded & set(fl.labels):
        entry["occluded"] = sorted(occluded & set(fl.labels))
    if record.get("note"):
        entry["note"] = record["note"]  # for a colleague
    return slips, occluded


def export_frame(reader: FrameReader, stem: str, settings: Settings | None = None, model: FieldModel | None = None,
                 view: FrameView | None = None, gate_px: float = GATE_PX) -> FrameExport:
    """The frame's export: a reviewed frame's labels as reviewed (:func:`reviewed_labels`),
    another's calibrated with ``settings`` (default: the reader's; ``view``: the frame's view
    under them when the caller has it). Points beyond the outlier gate (``gate_px`` at 960x540)
    are flagged, not exported as visible ground truth."""
    model = model or load_field_model()
    record = reader.edits.get(stem) if reader.edits is not None else {}
    fl = _frame_labels(reader, stem, record, settings, model, view)
    W, H = fl.size
    flagged = gate(fl, gate_px)
    entry = {**edits_entry(reader, stem), "calibrated": fl.camera is not None, "error": fl.error,
             "labels": fl.basis, "flagged": len(flagged)}
    slips, occluded = _entry_extras(entry, record, fl)
    try:
        ann = reader.annotation(stem, record)
    except DataError as exc:
        ann, entry["error"] = None, entry["error"] or str(exc)
    if ann is None and not fl.labels and entry["error"]:  # unreadable: no labels
        entry["exported"] = False
        return FrameExport(stem, entry)
    if ann is None and not fl.labels and fl.basis == "unreviewed":
        # nothing is known of its markings: an empty label file would say "no keypoints here"
        entry["exported"] = False
        entry["empty"] = "nothing to export: no annotation, no detections, no keypoint placed by hand"
        return FrameExport(stem, entry)
    entry["exported"] = True
    files = {}
    if ann is not None:
        files[f"annotations/{stem}.json"] = dumps(annotation_to_json(ann)).encode()
    kps = {}
    for kid, label in fl.labels.items():
        kps[str(kid)] = {"x": label.x, "y": label.y, "visible": inside(label, fl.size) and kid not in occluded,
                         "occluded": kid in occluded, "set": label.set, "provenance": label.provenance,
                         "residual": label.residual, "flagged": kid in flagged, "slip": str(kid) in slips}
    reviewed = fl.basis != "unreviewed"
    homography = frame_homography(fl.camera, fl.size)
    files[f"keypoints/{stem}.json"] = dumps({"image_size": [W, H], "reviewed": reviewed, "review": record.get("review"),
                                             "keypoints": kps, "homography": homography}).encode()
    if fl.camera is not None:
        files["cameras/" + camera_member_name(stem)] = dumps(fl.camera).encode()
    flat: list[object] = [0.0] * (3 * N_KEYPOINTS)
    for key, k in kps.items():
        i = int(key) - 1
        # COCO v: 2 visible ground truth, 1 labelled but not visible (outside the image, or occluded), 0 flagged
        flat[3 * i:3 * i + 3] = [k["x"], k["y"], 0 if k["flagged"] else 2 if k["visible"] else 1]
    image_id = reader.index_of(stem) + 1  # the frame's place in the dataset: the same whatever is exported
    frame = reader.ds.frame(stem)
    image = {"id": image_id, "file_name": Path(frame.image_path).name if frame.has_image else None,
             "stem": stem, "width": W, "height": H, "reviewed": reviewed}
    annotation = {"id": image_id, "image_id": image_id, "category_id": 1, "keypoints": flat,
                  "num_keypoints": sum(1 for i in range(N_KEYPOINTS) if flat[3 * i + 2] == 2)}
    return FrameExport(stem, entry, files, image, annotation, homography, fl.camera)


def frame_homography(camera: dict | None, size: tuple[int, int]) -> list[list[float]] | None:
    """The 3x3 homography, ground plane metres -> pixels of a ``size`` frame, of a 960x540
    SoccerNet camera dict (normalised so that its last entry is 1); None without a camera."""
    if camera is None:
        return None
    H = Camera.from_soccernet(camera).scaled(*size).homography()
    return (H / H[2, 2]).tolist()


class ExportWriter:
    """Collects :class:`FrameExport` parts (in any order) and writes the export: the label files
    as they come, ``coco_keypoints.json`` and ``manifest.json`` (in dataset order) at the end.

    ``out``: a folder, a ``.zip`` (written beside and moved in place at :meth:`close`: a failed
    export leaves no zip), or None (:meth:`close` returns the files, for the app's download).
    """

    def __init__(self, reader: FrameReader, out: Path | None, include_all: bool = False, gate_px: float = GATE_PX):
        self.out = None if out is None else Path(out)
        self._order = {s: i for i, s in enumerate(reader.stems)}
        self.manifest: dict[str, Any] = {"source": reader.data.resolve().name, "edits": reader.edits_folder.root.name,
                         "exported": time.strftime("%Y-%m-%dT%H:%M:%S"), "include_all": include_all,
                         "gate_px_at_960x540": float(gate_px), "flagged": 0, "frames": {}}
        self._parts: list[tuple[int, str, dict, dict | None, dict | None]] = []
        self._homographies: dict[str, list[list[float]]] = {}
        self.files: dict[str, bytes] = {}
        self._zip = None
        if self.out is not None and self.out.suffix == ".zip":
            self._zip = ZipStream(self.out, key=str, keep_partial=False)

    def add(self, part: FrameExport) -> None:
        for name, data in part.files.items():
            self._write(name, data)
        if part.homography is not None:
            self._homographies[part.stem] = part.homography
        self._parts.append((self._order[part.stem], part.stem, part.entry, part.coco_image, part.coco_annotation))

    def _write(self, name: str, data: bytes) -> None:
        if self._zip is not None:
            self._zip.add(name, data)
        elif self.out is not None:
            path = self.out / name
            path.parent.mkdir(parents=True, exist_ok=True)  # annotations/<split>/ of a dataset in splits
            atomic_write_bytes(path, data)
        else:
            self.files[name] = data

    def close(self) -> dict[str, bytes]:
        """Write the COCO file and the manifest and finish the output; the files (for ``out=None``)."""
        coco: dict[str, list] = {"images": [], "annotations": [],
                "categories": [{"id": 1, "name": "pitch", "keypoints": [str(i) for i in range(1, N_KEYPOINTS + 1)],
                                "skeleton": []}]}
        for _, stem, entry, image, annotation in sorted(self._parts, key=lambda p: p[0]):
            self.manifest["frames"][stem] = entry
            self.manifest["flagged"] += entry.get("flagged", 0)
            if image is not None:
                coco["images"].append(image)
                coco["annotations"].append(annotation)
        self._write("coco_keypoints.json", dumps(coco).encode())
        order = sorted(self._homographies, key=self._order.__getitem__)
        self._write("homographies.json", dumps({s: self._homographies[s] for s in order}, indent=1).encode())
        self._write("manifest.json", dumps(self.manifest, indent=1).encode())
        if self._zip is not None:
            self._zip.close()
        return self.files

    def discard(self) -> None:
        """Give up (an error or Ctrl+C): a zip output is not written."""
        if self._zip is not None:
            self._zip.discard()

    def __enter__(self) -> ExportWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.discard()


def export_files(reader: FrameReader, include_all: bool = False, settings: Settings | None = None,
                 model: FieldModel | None = None, gate_px: float = GATE_PX) -> dict[str, bytes]:
    """``{relative path: content}`` of the export (see the module docstring); unreviewed frames
    are calibrated with ``settings`` (default: the reader's)."""
    with ExportWriter(reader, None, include_all, gate_px) as writer:
        for stem in export_stems(reader, include_all):
            writer.add(export_frame(reader, stem, settings, model, gate_px=gate_px))
        return writer.close()


def read_export_zip(path: Path) -> tuple[dict[str, bytes], dict]:
    """An export zip read back: (its members but the manifest, the manifest without its date),
    the whole of what two exports of the same labels agree on."""
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    manifest = json.loads(members.pop("manifest.json"))
    manifest.pop("exported")
    return members, manifest


def write_export(reader: FrameReader, out: Path, include_all: bool = False, settings: Settings | None = None,
                 parts: Iterable[FrameExport] | None = None, gate_px: float = GATE_PX) -> dict[str, dict]:
    """Write the export to a folder, or to a zip when ``out`` ends in .zip; ``parts``: the frames'
    exports when computed elsewhere (a cluster), else computed here with ``settings``. Returns the
    manifest's frames (stem -> entry; ``entry["exported"]`` False for unreadable frames)."""
    if parts is None:
        parts = (export_frame(reader, stem, settings, gate_px=gate_px) for stem in export_stems(reader, include_all))
    with ExportWriter(reader, out, include_all, gate_px) as writer:
        for part in parts:
            writer.add(part)
        writer.close()
    return writer.manifest["frames"]
