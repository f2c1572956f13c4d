"""Export corrected training labels: what the app's export button downloads and ``pnlviz export``
writes.

Layout (a folder or a zip):

* ``annotations/<stem>.json``: SoccerNet line annotation, with the corrected line points;
* ``keypoints/<stem>.json``: keypoint labels, ``{"image_size": [W, H], "keypoints": {"id": {"x",
  "y", "visible", "set"}}}`` in pixels, corrected keypoints included (hidden ones left out);
* ``cameras/camera_<stem>.json``: the calibrated camera at 960x540 (SoccerNet format);
* ``coco_keypoints.json``: COCO keypoints, one "pitch" instance per frame with the 73 keypoints
  (v = 2 inside the image, 1 labelled outside it, 0 absent);
* ``manifest.json``: what each exported frame carries and what was changed (names, not paths:
  the export does not say where the server's files live).

Only accepted and corrected frames are exported unless ``include_all``. A frame whose files
cannot be read is listed in the manifest with its error and gets no label files (an empty label
file would say "no keypoints", which is not what is known).
"""

from __future__ import annotations

import io
import json
import time
import zipfile
from pathlib import Path

from pnlviz.app.state import EVAL_SIZE, AppState, Settings
from pnlviz.data import atomic_write_bytes
from pnlviz.data.annotations import annotation_to_json
from pnlviz.data.jsonio import dumps

N_KEYPOINTS = 73


def export_files(state: AppState, include_all: bool = False, settings: Settings | None = None) -> dict[str, bytes]:
    """``{relative path: content}`` of the export (see the module docstring); the frames are
    calibrated with ``settings`` (default: the state's)."""
    files: dict[str, bytes] = {}
    coco = {"images": [], "annotations": [],
            "categories": [{"id": 1, "name": "pitch", "keypoints": [str(i) for i in range(1, N_KEYPOINTS + 1)],
                            "skeleton": []}]}
    manifest = {"source": state.data.resolve().name, "edits": state.edits.root.name,
                "exported": time.strftime("%Y-%m-%dT%H:%M:%S"), "include_all": include_all, "frames": {}}
    for image_id, stem in enumerate(state.stems, start=1):
        rec = state.edits.get(stem)
        review = rec.get("review")
        if not include_all and review not in ("accepted", "corrected"):
            continue
        view = state.view(stem, settings)
        W, H = view.size
        entry = {"review": review, "annotation_edited": rec.get("annotation") is not None,
                 "keypoints_edited": sorted(int(k) for k in (rec.get("keypoints") or {})),
                 "calibrated": bool(view.result is not None and view.result.ok), "error": view.error}
        manifest["frames"][stem] = entry
        if view.annotation is None and view.observations is None and view.error:  # unreadable: no labels
            entry["exported"] = False
            continue
        entry["exported"] = True
        if view.annotation is not None:
            files[f"annotations/{stem}.json"] = dumps(annotation_to_json(view.annotation)).encode()
        kps = {}
        obs = view.observations
        if obs is not None:
            for kid, (x, y), s in zip(obs.kp_ids, obs.kp_xy, obs.kp_sets):
                inside = bool(0 <= x < W and 0 <= y < H)
                kps[str(int(kid))] = {"x": float(x), "y": float(y), "visible": inside, "set": str(s)}
        files[f"keypoints/{stem}.json"] = dumps({"image_size": [W, H], "keypoints": kps}).encode()
        if entry["calibrated"]:
            files[f"cameras/camera_{stem}.json"] = dumps(view.result.camera.scaled(*EVAL_SIZE).to_soccernet()).encode()
        flat = [0.0] * (3 * N_KEYPOINTS)
        for key, k in kps.items():
            i = int(key) - 1
            flat[3 * i:3 * i + 3] = [k["x"], k["y"], 2 if k["visible"] else 1]
        frame = state.ds.frame(stem)
        coco["images"].append({"id": image_id, "file_name": Path(frame.image_path).name if frame.has_image else None,
                               "stem": stem, "width": W, "height": H})
        coco["annotations"].append({"id": image_id, "image_id": image_id, "category_id": 1, "keypoints": flat,
                                    "num_keypoints": sum(1 for k in kps.values() if k["visible"])})
    files["coco_keypoints.json"] = dumps(coco).encode()
    files["manifest.json"] = dumps(manifest, indent=1).encode()
    return files


def _zip(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in sorted(files.items()):
            zf.writestr(name, data)
    return buf.getvalue()


def export_zip_bytes(state: AppState, include_all: bool = False, settings: Settings | None = None) -> bytes:
    return _zip(export_files(state, include_all, settings))


def write_export(state: AppState, out: Path, include_all: bool = False) -> dict[str, dict]:
    """Write the export to a folder, or to a zip when ``out`` ends in .zip. Returns the
    manifest's frames (stem -> entry; ``entry["exported"]`` False for unreadable frames)."""
    out = Path(out)
    files = export_files(state, include_all)
    if out.suffix == ".zip":
        atomic_write_bytes(out, _zip(files))
    else:
        for name, data in files.items():
            atomic_write_bytes(out / name, data)
    return json.loads(files["manifest.json"])["frames"]
