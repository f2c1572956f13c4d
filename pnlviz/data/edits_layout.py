"""Where everything in an edits folder lives: the one place that names its files.

Layout::

    <edits>/frames/<stem>.json        a frame's record (:mod:`pnlviz.data.edits`: review, corrections,
                                      undo history, review snapshot); frames/<split>/<stem>.json for a
                                      dataset in splits
    <edits>/lock                      held by the one process writing here (its pid and URL inside)
    <edits>/dataset.json              the dataset the folder was made for (:mod:`pnlviz.data.edits_folder`)
    <edits>/clips/<clip>.json         the cuts a hand added or removed in a clip (:mod:`pnlviz.pipeline.clip`)
    <edits>/cache/summaries.jsonl     the background pass's per-frame summaries (:mod:`pnlviz.app.triage`)
    <edits>/cache/detections.jsonl    ... and the detector's results, kept between runs

Only the app (``pnlviz serve``) writes here; every command that reads an edits folder reads it
through the same names.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["EditsLayout"]


@dataclass(frozen=True)
class EditsLayout:
    """The paths of the edits folder at ``root``."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def frames(self) -> Path:
        return self.root / "frames"

    def record(self, stem: str) -> Path:
        """The record of frame ``stem`` (a split's frame ``valid/00042``: ``frames/valid/00042.json``)."""
        return self.frames / f"{stem}.json"

    @property
    def lock(self) -> Path:
        return self.root / "lock"

    @property
    def identity(self) -> Path:
        return self.root / "dataset.json"

    @property
    def clips(self) -> Path:
        return self.root / "clips"

    def cuts(self, clip: str) -> Path:
        """The hand cuts of clip ``clip`` (its name made safe for a file name)."""
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in clip)[:120] or "_"
        return self.clips / f"{safe}.json"

    @property
    def cache(self) -> Path:
        return self.root / "cache"

    @property
    def summaries(self) -> Path:
        return self.cache / "summaries.jsonl"

    @property
    def detections(self) -> Path:
        return self.cache / "detections.jsonl"

    def is_edits_folder(self) -> bool:
        """Whether something of an edits folder is there (its records, its lock or its identity)."""
        return any(p.exists() for p in (self.frames, self.lock, self.identity))
