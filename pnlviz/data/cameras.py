"""SoccerNet camera JSON files (``camera_<stem>.json``) and flat zips of them.

Cameras stay raw dicts here (as the official evaluator reads them); converting them to a camera
object is the geometry package's job. A camera dict must hold :data:`REQUIRED_CAMERA_KEYS`
(PnLCalib also writes ``rotation_matrix``; extra keys are kept).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any

from .atomic import atomic_write_text
from .errors import DataError, member_source
from .jsonio import as_number, describe, dumps, parse_json_bytes, read_file_bytes, to_jsonable
from .layout import keyed_members, member_name, natural_key, sort_stems
from .reading import frame_files, open_zip, read_file, read_zip_member
from .zipwriter import ZipStream

__all__ = [
    "REQUIRED_CAMERA_KEYS",
    "camera_member_name",
    "camera_stem",
    "camera_member",
    "camera_zip_order",
    "validate_camera_dict",
    "parse_camera_bytes",
    "read_camera_json",
    "write_camera_json",
    "read_camera_zip",
    "read_cameras",
    "write_camera_zip",
]

#: Keys of a SoccerNet camera JSON, with the number of values each holds (1 = a scalar).
_CAMERA_SHAPES: dict[str, int] = {
    "pan_degrees": 1,
    "tilt_degrees": 1,
    "roll_degrees": 1,
    "position_meters": 3,
    "x_focal_length": 1,
    "y_focal_length": 1,
    "principal_point": 2,
    "radial_distortion": 6,
    "tangential_distortion": 2,
    "thin_prism_distortion": 4,
}
REQUIRED_CAMERA_KEYS: tuple[str, ...] = tuple(_CAMERA_SHAPES)

_CAMERA_NAME = re.compile(r"camera_(.+)\.json")


def camera_member_name(stem: str) -> str:
    """File name of the camera of annotation ``<stem>.json``: ``camera_<stem>.json``; in the
    split's folder for a frame of a dataset in splits (``valid/camera_00042.json``)."""
    return member_name(stem, lambda base: f"camera_{base}.json")


def camera_stem(name: str) -> str | None:
    """``"camera_<stem>.json"`` -> ``"<stem>"``; None for any other file name."""
    m = _CAMERA_NAME.fullmatch(name)
    return m.group(1) if m else None


def camera_zip_order(name: str) -> tuple:
    """Sort key of the members of a camera zip: natural order of their stems."""
    stem = camera_stem(name)
    return natural_key(name if stem is None else stem)


#: Physical ranges of the camera values: (low, high, what the range means). Focal lengths and
#: the principal point are positive pixels (the point inside a frame of at most 100000 px), the
#: position within a kilometre of the centre spot, angles within two turns, distortion bounded.
CAMERA_RANGES: dict[str, tuple[float, float, str]] = {
    "pan_degrees": (-720.0, 720.0, "an angle in degrees"),
    "tilt_degrees": (-720.0, 720.0, "an angle in degrees"),
    "roll_degrees": (-720.0, 720.0, "an angle in degrees"),
    "position_meters": (-1000.0, 1000.0, "metres from the centre spot"),
    "x_focal_length": (0.0, 1e6, "a focal length in pixels"),
    "y_focal_length": (0.0, 1e6, "a focal length in pixels"),
    "principal_point": (0.0, 1e5, "pixels inside the frame"),
    "radial_distortion": (-100.0, 100.0, "a distortion coefficient"),
    "tangential_distortion": (-100.0, 100.0, "a distortion coefficient"),
    "thin_prism_distortion": (-100.0, 100.0, "a distortion coefficient"),
}
_OPEN_BELOW = ("x_focal_length", "y_focal_length", "principal_point")


def _check_number(value: Any, key: str, source: str) -> None:
    v = as_number(value)
    if v is None:
        raise DataError(source, f"camera key {key!r} must be a number, got {describe(value)}")
    if not math.isfinite(v):
        raise DataError(source, f"camera key {key!r} is not finite ({v})")
    low, high, meaning = CAMERA_RANGES[key]
    if v > high or v < low or (v == low and key in _OPEN_BELOW):
        bounds = f"{'(' if key in _OPEN_BELOW else '['}{low:g}, {high:g}]"
        raise DataError(source, f"camera key {key!r} = {v:g} is impossible ({meaning}: must lie in {bounds})")


def validate_camera_dict(obj: Any, source: str = "<camera>") -> dict:
    """Check a decoded camera JSON object; returns it unchanged (a dict).

    Raises :class:`DataError` naming the first missing key, or a value of the wrong shape
    (scalars for angles and focal lengths; 3, 2, 6, 2, 4 numbers for position, principal point,
    radial, tangential and thin-prism distortion).
    """
    if not isinstance(obj, Mapping):
        raise DataError(source, f"expected a JSON object with the camera parameters, got {describe(obj)}")
    for key, size in _CAMERA_SHAPES.items():
        if key not in obj:
            raise DataError(source, f"camera is missing key {key!r}")
        value = obj[key]
        if size == 1:
            _check_number(value, key, source)
            continue
        if not isinstance(value, (list, tuple)) or len(value) != size:
            raise DataError(source, f"camera key {key!r} must be a list of {size} numbers, got {describe(value)}"
                            + (f" of length {len(value)}" if isinstance(value, (list, tuple)) else ""))
        for v in value:
            _check_number(v, key, source)
    return obj if isinstance(obj, dict) else dict(obj)


def parse_camera_bytes(data: bytes | str, source: str) -> dict:
    """Decode and validate one camera JSON document."""
    return validate_camera_dict(parse_json_bytes(data, source), source)


def read_camera_json(path: str | os.PathLike) -> dict:
    """Read and validate one camera JSON file (raw dict)."""
    return parse_camera_bytes(read_file_bytes(path), os.fspath(path))


def _camera_text(camera: Mapping, source: str) -> str:
    cam = to_jsonable(dict(camera)) if isinstance(camera, Mapping) else camera
    validate_camera_dict(cam, source)
    try:
        return dumps(cam)
    except (TypeError, ValueError) as e:
        raise DataError(source, f"camera cannot be written as JSON: {e}") from None


def write_camera_json(path: str | os.PathLike, camera: Mapping) -> None:
    """Validate and write one camera JSON file atomically (numpy values become plain JSON)."""
    atomic_write_text(path, _camera_text(camera, os.fspath(path)))


def _camera_members(zf, zpath: str, splits: Collection[str]) -> dict[str, str]:
    """``{stem: member}`` of the cameras of an open zip (DataError for duplicates or stray folders)."""
    def refuse(err: DataError) -> None:
        raise err

    members, problem = keyed_members(frame_files(zpath, zf, camera_stem, refuse), splits)
    if problem:
        raise DataError(zpath, f"camera {problem}")
    found: dict[str, str] = {}
    for stem, name in members:
        if stem in found:
            raise DataError(zpath, f"camera of frame {stem!r} appears twice ({found[stem]!r} and {name!r})")
        found[stem] = name
    return found


def read_camera_zip(path: str | os.PathLike, on_error: Callable[[DataError], Any] | None = None,
                    splits: Collection[str] = ()) -> dict[str, dict]:
    """Read a zip of ``camera_<stem>.json`` files -> ``{stem: camera dict}`` in natural order.

    The files are normally at the top level; one folder level (all cameras in the same folder)
    is accepted too, and split folders (``valid/camera_00042.json`` is frame ``valid/00042``;
    ``splits``, the dataset's, names them when only one is there). Other members are ignored. Each camera is validated. A camera that cannot
    be read or validated raises DataError, or with ``on_error`` is passed to it and skipped.
    """
    zpath = os.fspath(path)
    with open_zip(path) as zf:
        found = _camera_members(zf, zpath, splits)
        out: dict[str, dict] = {}
        for stem in sort_stems(found):
            source = member_source(zpath, found[stem])
            try:
                out[stem] = parse_camera_bytes(read_zip_member(zf, found[stem], source), source)
            except DataError as err:
                if on_error is None:
                    raise
                on_error(err)
    return out


def camera_member(stem: str, camera: Mapping, zip_path: str | os.PathLike) -> tuple[str, str]:
    """``(member name, JSON text)`` of one camera in a camera zip (DataError if it is invalid)."""
    name = camera_member_name(stem)
    return name, _camera_text(camera, member_source(zip_path, name))


def write_camera_zip(path: str | os.PathLike, cameras: Mapping[str, Mapping]) -> None:
    """Write ``{stem: camera dict}`` as a flat zip of ``camera_<stem>.json``, atomically."""
    zpath = os.fspath(path)
    by_stem = {str(stem): cam for stem, cam in cameras.items()}
    if len(by_stem) != len(cameras):
        raise DataError(zpath, "two cameras have the same stem once written as text")
    members = [camera_member(stem, by_stem[stem], zpath) for stem in sort_stems(by_stem)]
    with ZipStream(zpath, keep_partial=False) as zs:
        for name, text in members:
            zs.add(name, text)


def read_cameras(path: str | os.PathLike, on_error: Callable[[str], Any] | None = None,
                 splits: Collection[str] = ()) -> tuple[dict[str, dict], list[str]]:
    """Read a zip (or folder) of ``camera_<stem>.json`` leniently -> ``({stem: dict}, problems)``.

    Unlike :func:`read_camera_zip`, a camera that cannot be read or validated (or
    whose file name is not valid UTF-8) is skipped with a one-line problem (``on_error(line)`` is
    called too) instead of failing the whole archive. Files at the top level are used; if there
    are none, one folder level, or split folders (as :func:`read_camera_zip`). A problem with the
    archive itself raises :class:`DataError`.
    """
    path = Path(path)
    problems: list[str] = []
    zf = None if path.is_dir() else open_zip(path)
    try:
        found = frame_files(path, zf, camera_stem, lambda err: problems.append(str(err)))
        members, problem = keyed_members(found, splits)
        if problem:
            problems.append(f"{os.fspath(path)}: camera {problem}")
        by_stem: dict[str, dict] = {}
        for stem, member in members:
            source = member_source(path, member) if zf else member
            try:
                data = read_zip_member(zf, member, source) if zf else read_file(member)
                by_stem[stem] = parse_camera_bytes(data, source)
            except DataError as e:
                problems.append(str(e))
    finally:
        if zf is not None:
            zf.close()
    if on_error is not None:
        for line in problems:
            on_error(line)
    return {s: by_stem[s] for s in sort_stems(by_stem)}, problems
