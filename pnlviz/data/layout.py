"""Names inside folders and zip archives: natural sort of stems, locating the frame folder."""

from __future__ import annotations

import re
import statistics
from collections.abc import Callable, Collection, Iterable

__all__ = ["MAX_CLIP_STEP", "MIN_CLIP_FRAMES", "clips", "clip_key", "video_clips", "natural_key", "sort_stems", "split_member", "find_root", "split_stem", "join_stem",
           "member_name", "keyed_members"]

_DIGITS = re.compile(r"([0-9]+)")


def natural_key(stem: str) -> tuple:
    """Sort key: ``"2" < "10"``, ``"frame2" < "frame10"``; ties broken by the raw string."""
    parts = []
    for i, tok in enumerate(_DIGITS.split(stem)):
        if i % 2:
            parts.append((1, int(tok), ""))
        elif tok:
            parts.append((0, 0, tok.lower()))
    return (tuple(parts), stem)


def sort_stems(stems: Iterable[str]) -> list[str]:
    """Stems in natural order (numeric when all digits)."""
    return sorted(stems, key=natural_key)


_FRAME_NUMBER = re.compile(r"^(.*?)([0-9]+)$")
_FRAME_WORD = re.compile(r"(?:img|image|frame)$", re.IGNORECASE)


def clip_key(stem: str) -> tuple[str, int]:
    """``(clip, frame number)`` of a video frame's stem: the trailing number is the frame, what
    comes before it (less separators and a word such as ``IMG`` or ``frame``) names the clip; a
    split's folder stays in front of the name (``"valid/clip7-IMG_012"`` -> ``("valid/clip7", 12)``)
    and is no name by itself (``"valid/00042"`` -> ``("", 42)``). ``"clip7-IMG_012"`` ->
    ``("clip7", 12)``; ``"00042"`` -> ``("", 42)``; no number -> ``(stem, 0)``."""
    split, base = split_stem(stem)
    m = _FRAME_NUMBER.match(base)
    if m is None:
        return stem, 0
    prefix = _FRAME_WORD.sub("", m.group(1).rstrip("-_. ")).rstrip("-_. ")
    return (join_stem(split, prefix) if prefix else ""), int(m.group(2))


def clips(stems: Iterable[str]) -> dict[str, list[str]]:
    """Stems grouped by :func:`clip_key`, each group in frame order, groups in natural order (the
    group ``""`` holds the stems that name no clip)."""
    out: dict[str, list[str]] = {}
    for stem in stems:
        out.setdefault(clip_key(stem)[0], []).append(stem)
    return {c: sorted(out[c], key=lambda s: (clip_key(s)[1], natural_key(s))) for c in sort_stems(out)}


#: a clip has at least this many frames
MIN_CLIP_FRAMES = 3
#: the largest median step between the frame numbers of a clip (a video dropped a frame here and there)
MAX_CLIP_STEP = 2


def video_clips(stems: Iterable[str]) -> dict[str, list[str]]:
    """The one rule for which frames of a dataset form a video clip, by their names (every caller
    uses it: ``pnlviz calibrate --temporal``, the app, its export, the benchmarks): stems that name
    a clip (``<clip>-IMG_<n>``, ``<clip>_frame<n>``, :func:`clip_key`), at least
    :data:`MIN_CLIP_FRAMES` of them, whose frame numbers follow each other (a median step of at most
    :data:`MAX_CLIP_STEP`). Plain numbered frames (``00001``, ``valid/00042``: a split is not a clip)
    and named picks of separate pictures (``wc14_3``, ``wc14_8``, ``wc14_11``) are not clips.
    ``{clip: [stems in frame order]}``. (Whether the frames then look like one video is the
    calibration's to say: :func:`pnlviz.calib.temporal.calibrate_clip` calls frames whose shots
    are mostly single frames unrelated pictures.)"""
    out = {}
    for name, members in clips(stems).items():
        if not name or len(members) < MIN_CLIP_FRAMES:
            continue
        numbers = [clip_key(s)[1] for s in members]
        if statistics.median(b - a for a, b in zip(numbers[:-1], numbers[1:])) <= MAX_CLIP_STEP:
            out[name] = members
    return out


def is_junk(name: str) -> bool:
    """Zip/OS noise: macOS resource forks, hidden files, folder entries."""
    parts = name.split("/")
    return name.endswith("/") or any(p.startswith(".") or p == "__MACOSX" for p in parts if p)


def split_member(name: str) -> tuple[str, str]:
    """``"a/b/c.json"`` -> ``("a/b/", "c.json")``; ``"c.json"`` -> ``("", "c.json")``."""
    head, sep, tail = name.rpartition("/")
    return (head + sep, tail)


def find_root(names: Iterable[str], is_wanted) -> str:
    """The folder prefix (``""`` or ``"dir/"``) holding the wanted files of an archive.

    Files at the top level win; otherwise, if every wanted file sits in one and the same
    single top-level folder, that folder is the root. ``is_wanted(basename)`` selects files.
    """
    top_dirs = set()
    for name in names:
        if is_junk(name):
            continue
        prefix, base = split_member(name)
        if not is_wanted(base):
            continue
        if prefix == "":
            return ""
        if prefix.count("/") == 1:
            top_dirs.add(prefix)
    if len(top_dirs) == 1:
        return top_dirs.pop()
    return ""


# -- stems of datasets in splits (pnlviz.data.splits) ---------------------------------------------
def split_stem(stem: str) -> tuple[str, str]:
    """``"valid/00042"`` -> ``("valid", "00042")``; a plain stem -> ``("", stem)``."""
    split, _, base = stem.rpartition("/")
    return split, base


def join_stem(split: str, stem: str) -> str:
    """``("valid", "00042")`` -> ``"valid/00042"``; no split -> the stem."""
    return f"{split}/{stem}" if split else stem


def member_name(stem: str, name_of: Callable[[str], str]) -> str:
    """The name of a per-frame output file: ``name_of(base)`` under the split's folder
    (``member_name("valid/00042", lambda s: f"camera_{s}.json")`` -> ``"valid/camera_00042.json"``)."""
    split, base = split_stem(stem)
    return join_stem(split, name_of(base))


def _last(prefix: str) -> str:
    return prefix.rstrip("/").rpartition("/")[2]


def keyed_members(found: dict[str, list[tuple[str, str]]],
                  splits: Collection[str] = ()) -> tuple[list[tuple[str, str]], str | None]:
    """Which per-frame files of an output (a camera zip, a prediction zip or folder) are used, and
    the frame stem of each. ``found``: ``{folder prefix: [(stem, name)]}``, the prefix ``""``,
    ``"a/"`` or ``"a/b/"``. Returns ``([(stem, name)], problem or None)``:

    * files at the top level give their stems;
    * files in a folder named after one of ``splits`` (the dataset's) give ``"<split>/<stem>"``;
    * with no file at the top level: the files of a single folder give their stems (a zip of a
      folder), and files in several folders side by side give ``"<folder>/<stem>"`` (the output
      of a dataset in splits, :mod:`pnlviz.data.splits`);
    * other files are not used, and ``problem`` says where they are.
    """
    used = list(found.get("", []))
    folders = sorted(p for p in found if p)
    if splits:
        named = [p for p in folders if _last(p) in splits]
        used += [(join_stem(_last(p), s), n) for p in named for s, n in found[p]]
        folders = [p for p in folders if p not in named]
        if used:
            return used, _unused(folders)
    elif used:
        return used, _unused(folders)
    if len(folders) == 1:
        return list(found[folders[0]]), None
    parents = {p.rstrip("/").rpartition("/")[0] for p in folders}
    if folders and len(parents) == 1 and len({_last(p) for p in folders}) == len(folders):
        return [(join_stem(_last(p), s), n) for p in folders for s, n in found[p]], None
    return [], _unused(folders)


def _unused(folders: list[str]) -> str | None:
    if not folders:
        return None
    listed = ", ".join(repr(f) for f in folders[:3]) + (", ..." if len(folders) > 3 else "")
    return f"files in other folders are not used ({listed}): expected them at the top level or in split folders"
