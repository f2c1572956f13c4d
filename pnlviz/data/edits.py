"""The edits folder: review statuses and label corrections, beside the data and never over it.

Layout::

    <edits>/frames/<stem>.json          {"review": "accepted"|"corrected"|"rejected",
                                         "annotation": {SoccerNet annotation},
                                         "keypoints": {"<id>": [x, y] | null},   # pixels; null = absent
                                         "occluded": [<id>, ...],     # labelled but hidden behind something (COCO v=1)
                                         "note": "free text for a colleague",
                                         "history": {"undo": [step, ...], "redo": [step, ...]},
                                         "snapshot": {what was on screen when reviewed},
                                         "updated": <unix time>}
        a step: the fields one user action changed, as they were before it ({"review": null, ...})
    <edits>/frames/<split>/<stem>.json  the same, for a frame of a dataset in splits (stem "<split>/<stem>")
    <edits>/frames/<stem>.json.damaged  a file that failed validation, moved aside (kept, never deleted)
    <edits>/lock                        held by the one process writing here (its pid and URL inside)

(every path of the folder is named in one place: :mod:`pnlviz.data.edits_layout`)

Every record is validated when it is read and before it is written (the same rules), so what is
on disk is always something the app can use. Writes are atomic (a crash leaves the old file or
the new one) and every read-modify-write of a frame runs under that frame's lock, so concurrent
edits from several browser tabs are applied one after the other, none lost. A user action is
one undo step kept in the record (:meth:`EditsStore.act`, :meth:`EditsStore.step`), so the
history outlives the server.

The checks of an edit before it is made (an id of the catalogue, a position on or near the frame)
are pure functions here too (:func:`check_keypoint_id`, :func:`check_position`): whoever edits
(the app, a script) refuses the same things with the same :class:`EditError`.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import os
import socket
import threading
import time
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from typing import Any

from pnlviz.data.annotations import parse_annotation
from pnlviz.data.atomic import atomic_write_text
from pnlviz.data.edits_layout import EditsLayout
from pnlviz.data.errors import DataError
from pnlviz.data.jsonio import as_number, describe, dumps
from pnlviz.data.reading import read_file
from pnlviz.data.snapshot import edits_digest, validate_snapshot
from pnlviz.conventions import REVIEW_STATES as _REVIEW_STATES

REVIEW_STATES = _REVIEW_STATES
#: the fields a record may hold; anything else is dropped when it is read ("frame": the identity of
#: the frame it was written for, :mod:`pnlviz.data.edits_folder`)
FIELDS = ("review", "annotation", "keypoints", "occluded", "note", "history", "snapshot", "updated", "frame")
#: the fields an undo step may restore
UNDOABLE = ("annotation", "keypoints", "occluded", "note", "review")
#: the longest note on a frame (characters)
MAX_NOTE = 2000
#: undo steps kept per frame (and per direction)
HISTORY_LIMIT = 100
#: seconds within which actions of one merge key are one undo step (:meth:`EditsStore.act`)
MERGE_S = 2.0
#: keypoint coordinates are pixels: anything larger is not a position in a frame
MAX_COORDINATE = 1e6
#: how far outside the frame a point may be placed, as a fraction of its size (as the
#: annotations' coordinate range allows: -0.5..1.5)
PLACEMENT_MARGIN = 0.5


class EditsFolderError(RuntimeError):
    """The edits folder cannot be used: not writable, or in use by another process."""


class EditError(ValueError):
    """An edit that cannot be applied (unknown frame or id, a position off the frame, ...)."""


def default_edits_dir(data: Path) -> Path:
    """``<data>.edits`` beside a folder or zip: never inside or over the source. When that folder
    cannot be written (read-only data), ``~/.pnlviz/edits/<name>-<hash of the path>``."""
    data = Path(data).resolve()
    name = data.name[:-4] if data.suffix == ".zip" else data.name
    beside = data.parent / f"{name}.edits"
    if beside.is_dir() and os.access(beside, os.W_OK) or not beside.exists() and os.access(data.parent, os.W_OK):
        return beside
    digest = hashlib.sha1(str(data).encode()).hexdigest()[:10]
    return Path.home() / ".pnlviz" / "edits" / f"{name}-{digest}"


@functools.cache
def keypoint_ids() -> frozenset[int]:
    """The catalogue's keypoint ids (PnLCalib's 1..73)."""
    from pnlviz.field.model import load_field_model

    return frozenset(int(i) for i in load_field_model().keypoint_ids)


def validate_keypoint(kid: Any, value: Any, source: str) -> tuple[str, list[float] | None]:
    """``("<id>", [x, y] | None)`` of one keypoint edit; DataError when the id is not in the
    catalogue or the value is not null or two finite numbers."""
    text = str(kid)
    if not text.isdigit() or int(text) not in keypoint_ids():
        raise DataError(source, f"keypoint id {text[:20]!r} is not in the catalogue (1..73)")
    if value is None:
        return str(int(text)), None
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise DataError(source, f"keypoint {text}: expected [x, y] or null, got {describe(value)}")
    xy = [v for v in (as_number(v) for v in value) if v is not None and math.isfinite(v) and abs(v) <= MAX_COORDINATE]
    if len(xy) != 2:
        raise DataError(source, f"keypoint {text}: [x, y] must be two finite pixel coordinates, got {value!r:.60}")
    return str(int(text)), xy


def check_keypoint_id(kid: Any) -> int:
    """The id of a keypoint to edit, an integer of the catalogue; EditError otherwise. Nothing is
    coerced: ``5.5``, ``True`` and ``"7"`` are refused (an id comes from the catalogue as an int)."""
    import numpy as np

    if isinstance(kid, (bool, np.bool_)) or not isinstance(kid, (int, np.integer)):
        raise EditError(f"keypoint id must be an integer, got {type(kid).__name__} {str(kid)[:20]!r}")
    kid = int(kid)
    if kid not in keypoint_ids():
        raise EditError(f"keypoint id {kid} is not in the catalogue (1..73)")
    return kid


def check_position(x: Any, y: Any, size: tuple[int, int], stem: str) -> tuple[float, float]:
    """A pixel position to put a point at on frame ``stem`` of ``size`` (W, H): two finite numbers
    within :data:`PLACEMENT_MARGIN` of the frame; EditError otherwise."""
    W, H = size
    try:
        x, y = float(x), float(y)
    except (TypeError, ValueError):
        raise EditError(f"a position must be two numbers, got {x!r}, {y!r}") from None
    m = PLACEMENT_MARGIN
    if not (math.isfinite(x) and math.isfinite(y) and -m * W <= x <= (1 + m) * W and -m * H <= y <= (1 + m) * H):
        raise EditError(f"position ({x:.6g}, {y:.6g}) is off the {W}x{H} frame of {stem} "
                        "by more than half its size")
    return x, y


def validate_record(obj: Any, source: str, checked_before: Collection[int] = ()) -> dict:
    """A checked copy of an edit record (see the module docstring); DataError on anything else.
    ``checked_before``: see :func:`validate_history`."""
    if not isinstance(obj, Mapping):
        raise DataError(source, f"an edit record must be a JSON object, got {describe(obj)}")
    rec: dict = {}
    review = obj.get("review")
    if review is not None:
        if review not in REVIEW_STATES:
            raise DataError(source, f"review must be one of {', '.join(REVIEW_STATES)} or null, got {describe(review)}")
        rec["review"] = review
    if obj.get("annotation") is not None:
        parse_annotation(obj["annotation"], source)  # raises DataError
        rec["annotation"] = obj["annotation"]
    kps = obj.get("keypoints")
    if kps is not None:
        if not isinstance(kps, Mapping):
            raise DataError(source, f'"keypoints" must be an object of id -> [x, y] | null, got {describe(kps)}')
        rec["keypoints"] = dict(validate_keypoint(k, v, source) for k, v in kps.items())
    occluded = obj.get("occluded")
    if occluded is not None:
        if not isinstance(occluded, list) or not all(type(k) is int and k in keypoint_ids() for k in occluded):
            raise DataError(source, f'"occluded" must be a list of keypoint ids (1..73), got {describe(occluded)}')
        rec["occluded"] = sorted(set(occluded))
    note = obj.get("note")
    if note is not None:
        if not isinstance(note, str) or len(note) > MAX_NOTE:
            raise DataError(source, f'"note" must be text of at most {MAX_NOTE} characters, got {describe(note)}')
        rec["note"] = note
    if obj.get("snapshot") is not None:
        rec["snapshot"] = validate_snapshot(obj["snapshot"], source)
    history = obj.get("history")
    if history is not None:
        rec["history"] = validate_history(history, source, checked_before)
    updated = as_number(obj.get("updated"))
    if updated is not None and math.isfinite(updated):
        rec["updated"] = updated
    frame = obj.get("frame")
    if frame is not None:
        size = frame.get("size") if isinstance(frame, Mapping) else None
        if not (isinstance(frame, Mapping) and isinstance(frame.get("digest"), str) and len(frame["digest"]) <= 128
                and (size is None or (isinstance(size, list) and len(size) == 2
                                      and all(type(v) is int and 0 < v < 1 << 20 for v in size)))):
            raise DataError(source, f'"frame" must be {{"size": [W, H] | null, "digest": "..."}}, got {describe(frame)}')
        rec["frame"] = {"size": size, "digest": frame["digest"]}
    return rec


def validate_history(obj: Any, source: str, checked_before: Collection[int] = ()) -> dict:
    """A checked copy of a record's undo history: ``{"undo": [step], "redo": [step]}``, each step
    a mapping of some :data:`UNDOABLE` fields to their values (null: absent), valid as a record's.
    ``checked_before``: ids of step objects that were checked already (kept as they are)."""
    if not isinstance(obj, Mapping):
        raise DataError(source, f'"history" must be an object with "undo" and "redo" lists, got {describe(obj)}')
    out = {}
    for side in ("undo", "redo"):
        steps = obj.get(side, [])
        if not isinstance(steps, list):
            raise DataError(source, f'history "{side}" must be a list, got {describe(steps)}')
        checked = []
        for step in steps[-HISTORY_LIMIT:]:
            if id(step) in checked_before:
                checked.append(step)
                continue
            if not isinstance(step, Mapping) or not step or any(k not in UNDOABLE for k in step):
                raise DataError(source, f"an undo step is an object of {', '.join(UNDOABLE)}, got {describe(step)}")
            values = validate_record({k: v for k, v in step.items() if v is not None}, source)
            checked.append({k: values.get(k) for k in step})
        out[side] = checked
    return out


_EMPTY_DIGEST = edits_digest({})


class _Unchanged(Exception):
    """Raised inside an edit transaction that changes nothing: no write, no undo step."""


def _record_text(rec: dict) -> str:
    """A record as JSON: one line without spaces (with a hundred undo steps of a whole annotation
    a record is half a megabyte, and an indented one is encoded by Python's slow encoder on every
    edit); plain JSON types only after validation, numpy ones converted if any slipped in."""
    try:
        return json.dumps(rec, allow_nan=False, separators=(",", ":"))
    except TypeError:
        return dumps(rec)


class EditsStore:
    """One validated JSON record per frame in ``root/frames/``.

    ``writable=True`` (the app): the folder is created, locked for this process (a second
    process gets :class:`EditsFolderError`), leftovers of interrupted writes are removed, and
    damaged records are moved aside as ``*.damaged``. ``writable=False`` (``pnlviz export``):
    nothing is created or moved; damaged records are skipped. Either way every problem is one
    line in :attr:`warnings`, and a frame whose record is damaged falls back to its source labels.
    """

    def __init__(self, root: Path, *, writable: bool = True):
        self.root = Path(root)
        self.layout = EditsLayout(self.root)
        self.frames = self.layout.frames
        self.writable = writable
        self.warnings: list[str] = []
        self._cache: dict[str, dict] = {}
        self._locks: dict[str, threading.RLock] = {}
        self._locks_lock = threading.Lock()
        self._lock_file: int | None = None
        #: ``identity(stem)``: the frame's identity, kept in every record written
        #: (:func:`pnlviz.data.edits_folder.frame_identity`; None: none kept)
        self.identity: Callable[[str], dict] | None = None
        #: stem -> (merge key, time, undo steps) of the frame's last action that named a merge key
        self._merging: dict[str, tuple[object, float, int]] = {}
        if writable:
            self._take_folder()
            self._remove_leftovers()
        self._load()

    # ------------------------------------------------------------------ the folder
    def _take_folder(self) -> None:
        try:
            self.frames.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.layout.lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise EditsFolderError(f"{self.root}: the edits folder cannot be written ({exc.strerror or exc}); "
                                   f"give --edits a folder you can write") from None
        try:
            import fcntl

            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # no advisory locks on this platform: one server per folder is on the user
            pass
        except OSError:
            holder = os.read(fd, 4096).decode("utf-8", "replace").strip()
            os.close(fd)
            raise EditsFolderError(f"{self.root} is in use by another pnlviz process ({holder or 'unknown'}); "
                                   f"stop it, or give this one another --edits folder") from None
        self._lock_file = fd
        self.describe_holder()

    def describe_holder(self, url: str | None = None) -> None:
        """Write who holds the folder (pid, host, URL) into the lock file, for the message a second
        process shows."""
        if self._lock_file is None:
            return
        text = f"pid {os.getpid()} on {socket.gethostname()}" + (f", {url}" if url else "") + \
            f", since {time.strftime('%Y-%m-%d %H:%M:%S')}"
        os.ftruncate(self._lock_file, 0)
        os.pwrite(self._lock_file, text.encode(), 0)

    def _remove_leftovers(self) -> None:
        """Temporary files of writes that a crash interrupted (``.<name>.<random>.tmp``)."""
        for p in [*self.frames.glob(".*.tmp"), *self.frames.glob("*/.*.tmp")]:
            with contextlib.suppress(OSError):
                p.unlink()

    def close(self) -> None:
        """Release the folder (another process may then take it)."""
        if self._lock_file is not None:
            os.close(self._lock_file)  # closing the descriptor releases the flock
            self._lock_file = None

    def __enter__(self) -> EditsStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ reading
    def _load(self) -> None:
        if not self.frames.is_dir():
            return
        for p in sorted([*self.frames.glob("*.json"), *self.frames.glob("*/*.json")]):  # */: split folders
            try:
                data = read_file(p)  # capped; a FIFO or a device is refused, never read
                rec = validate_record(json.loads(data), str(p))
            except (OSError, ValueError, RecursionError) as exc:  # DataError and JSONDecodeError are ValueErrors
                self._damaged(p, exc)
                continue
            self._cache[p.relative_to(self.frames).with_suffix("").as_posix()] = rec

    def _damaged(self, path: Path, exc: Exception) -> None:
        reason = exc.problem if isinstance(exc, DataError) else str(exc) or type(exc).__name__
        if not self.writable:
            self.warnings.append(f"{path}: damaged edit record ignored ({reason})")
            return
        target = path.with_name(path.name + ".damaged")
        n = 1
        while target.exists():
            target = path.with_name(f"{path.name}.damaged.{n}")
            n += 1
        try:
            os.replace(path, target)
            self.warnings.append(f"{path}: damaged edit record moved to {target.name} ({reason}); "
                                 f"the frame shows its source labels")
        except OSError as move_error:
            self.warnings.append(f"{path}: damaged edit record ignored ({reason}); cannot move it aside: {move_error}")

    def get(self, stem: str) -> dict:
        """A copy of the frame's record ({} when it has none). The undo steps in its history are
        not copied (a hundred of them can be most of the record): they are never changed in
        place, only added, removed and moved between the lists."""
        rec = self._cache.get(stem)
        if not rec:
            return {}
        out = json.loads(json.dumps({k: v for k, v in rec.items() if k != "history"}))
        if "history" in rec:
            out["history"] = {side: list(steps) for side, steps in rec["history"].items()}
        return out

    def digest(self, stem: str) -> str:
        """The digest of what the frame's record changes (:func:`pnlviz.data.snapshot.edits_digest`),
        without copying it (records are replaced on a write, never changed in place)."""
        rec = self._cache.get(stem)
        return edits_digest(rec) if rec else _EMPTY_DIGEST

    def _checked_steps(self, stem: str) -> set[int]:
        """Ids of the undo steps of the frame's record as it is (all checked when it was)."""
        history = (self._cache.get(stem) or {}).get("history") or {}
        return {id(step) for steps in history.values() for step in steps}

    def review(self, stem: str) -> str | None:
        return self._cache.get(stem, {}).get("review")

    def counts(self) -> dict[str, int]:
        out = {s: 0 for s in REVIEW_STATES}
        for rec in list(self._cache.values()):
            if rec.get("review") in out:
                out[rec["review"]] += 1
        return out

    def stems(self) -> list[str]:
        return list(self._cache)

    # ------------------------------------------------------------------ writing
    def lock(self, stem: str) -> threading.RLock:
        """The frame's lock (re-entrant): hold it to make several steps one transaction."""
        with self._locks_lock:
            return self._locks.setdefault(stem, threading.RLock())

    @contextlib.contextmanager
    def edit(self, stem: str) -> Iterator[dict]:
        """Read-modify-write of one frame's record under its lock: the block changes the yielded
        copy, which is validated and written atomically when the block ends without an error
        (nothing is written, nor cached, when it raises, or when the write fails)."""
        if not self.writable:
            raise EditsFolderError(f"{self.root}: opened read-only")
        with self.lock(stem):
            rec = self.get(stem)
            yield rec
            rec = {k: v for k, v in rec.items() if v is not None and k in FIELDS}
            rec["updated"] = time.time()
            if self.identity is not None:
                rec["frame"] = self.identity(stem)
            path = self.layout.record(stem)  # a split's frame: frames/<split>/<stem>.json
            rec = validate_record(rec, str(path), self._checked_steps(stem))
            path.parent.mkdir(exist_ok=True)
            atomic_write_text(path, _record_text(rec))
            self._cache[stem] = rec

    def update(self, stem: str, **changes) -> dict:
        """Set (or with None, remove) fields of a frame's record; returns the new record."""
        with self.edit(stem) as rec:
            rec.update(changes)
        return self.get(stem)

    def act(self, stem: str, change: Callable[[dict], None], *, corrected: bool = True, merge: object = None) -> bool:
        """One user action on one frame: ``change(record)`` under the frame's lock (``corrected``:
        the frame becomes "corrected"), one undo step kept in the record, written at once. False
        when nothing changed (no write, no step); an OSError of the write reaches the caller and
        nothing changes. ``merge``: actions with the same key in a row, each within
        :data:`MERGE_S` of the last and nothing else done on the frame between, are one undo step
        (the arrow-key nudges of one point)."""
        now = time.monotonic()
        try:
            with self.edit(stem) as rec:
                before = {k: rec.get(k) for k in UNDOABLE}
                change(rec)
                if corrected:
                    rec["review"] = "corrected"
                step = {k: before[k] for k in UNDOABLE if rec.get(k) != before[k]}
                if not step:
                    raise _Unchanged
                history = rec.get("history") or {}
                undo = list(history.get("undo", []))
                last = self._merging.get(stem)
                if not (merge is not None and last is not None and last[0] == merge and now - last[1] < MERGE_S
                        and last[2] == len(undo) and undo):
                    undo = (undo + [step])[-HISTORY_LIMIT:]
                rec["history"] = {"undo": undo, "redo": []}
        except _Unchanged:
            return False
        if merge is not None:
            self._merging[stem] = (merge, now, len(rec["history"]["undo"]))
        else:
            self._merging.pop(stem, None)
        return True

    def keep_review(self, stem: str) -> None:
        """The frame's review status, set by hand, stays when its edits are undone: the undo and
        redo steps no longer carry the status the edits set with them (steps left empty go)."""
        with self.lock(stem):
            history = (self._cache.get(stem) or {}).get("history")
            if not history or not any("review" in step for steps in history.values() for step in steps):
                return
            with self.edit(stem) as rec:
                rec["history"] = {side: [{k: v for k, v in step.items() if k != "review"} for step in steps
                                         if set(step) != {"review"}] for side, steps in history.items()}
            self._merging.pop(stem, None)

    def step(self, stem: str, back: bool = True) -> bool:
        """Take back the frame's last action (``back``), or do again the last one taken back;
        False when there is none."""
        source, target = ("undo", "redo") if back else ("redo", "undo")
        try:
            with self.edit(stem) as rec:
                history = rec.get("history") or {}
                steps = list(history.get(source, []))
                if not steps:
                    raise _Unchanged
                step = steps.pop()
                undone = {k: rec.get(k) for k in step}
                rec.update(step)
                rec["history"] = {source: steps, target: (list(history.get(target, [])) + [undone])[-HISTORY_LIMIT:]}
        except _Unchanged:
            return False
        return True

    def history(self, stem: str) -> tuple[int, int]:
        """(undo steps, redo steps) the frame has."""
        h = (self._cache.get(stem) or {}).get("history") or {}
        return len(h.get("undo", [])), len(h.get("redo", []))
