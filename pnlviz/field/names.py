"""SoccerNet line-class names: the exact keys of the official evaluator (``SoccerPitch.lines_classes``).

``Goal left post left `` carries a trailing space in the evaluator and in every annotation file.
We accept it with or without the space and always write it with the space.
"""

from __future__ import annotations

import difflib

#: The 23 straight classes, in the order of PnLCalib's line ids 1..23.
STRAIGHT_CLASSES: tuple[str, ...] = (
    "Big rect. left bottom",
    "Big rect. left main",
    "Big rect. left top",
    "Big rect. right bottom",
    "Big rect. right main",
    "Big rect. right top",
    "Goal left crossbar",
    "Goal left post left ",
    "Goal left post right",
    "Goal right crossbar",
    "Goal right post left",
    "Goal right post right",
    "Middle line",
    "Side line bottom",
    "Side line left",
    "Side line right",
    "Side line top",
    "Small rect. left bottom",
    "Small rect. left main",
    "Small rect. left top",
    "Small rect. right bottom",
    "Small rect. right main",
    "Small rect. right top",
)
CIRCLE_CLASSES: tuple[str, ...] = ("Circle central", "Circle left", "Circle right")
#: Classes that may appear in annotations and are accepted but carry no geometry.
IGNORED_CLASSES: tuple[str, ...] = ("Goal unknown", "Line unknown")
#: Every class with geometry in the pitch model (26).
MODEL_CLASSES: tuple[str, ...] = STRAIGHT_CLASSES + CIRCLE_CLASSES
#: Every class name the evaluator knows (28).
ALL_CLASSES: tuple[str, ...] = tuple(sorted(MODEL_CLASSES + IGNORED_CLASSES))

#: PnLCalib line ids (1..23) -> class name.
LINE_ID_TO_CLASS: dict[int, str] = {i + 1: name for i, name in enumerate(STRAIGHT_CLASSES)}
CLASS_TO_LINE_ID: dict[str, int] = {name: i for i, name in LINE_ID_TO_CLASS.items()}

#: The evaluator's left/right mirror table (central symmetry through the pitch centre).
MIRROR: dict[str, str] = {
    "Side line top": "Side line bottom",
    "Side line bottom": "Side line top",
    "Side line left": "Side line right",
    "Side line right": "Side line left",
    "Middle line": "Middle line",
    "Big rect. left top": "Big rect. right bottom",
    "Big rect. left bottom": "Big rect. right top",
    "Big rect. left main": "Big rect. right main",
    "Big rect. right top": "Big rect. left bottom",
    "Big rect. right bottom": "Big rect. left top",
    "Big rect. right main": "Big rect. left main",
    "Small rect. left top": "Small rect. right bottom",
    "Small rect. left bottom": "Small rect. right top",
    "Small rect. left main": "Small rect. right main",
    "Small rect. right top": "Small rect. left bottom",
    "Small rect. right bottom": "Small rect. left top",
    "Small rect. right main": "Small rect. left main",
    "Circle left": "Circle right",
    "Circle central": "Circle central",
    "Circle right": "Circle left",
    "Goal left crossbar": "Goal right crossbar",
    "Goal left post left ": "Goal right post left",
    "Goal left post right": "Goal right post right",
    "Goal right crossbar": "Goal left crossbar",
    "Goal right post left": "Goal left post left ",
    "Goal right post right": "Goal left post right",
    "Goal unknown": "Goal unknown",
    "Line unknown": "Line unknown",
}

#: Names after the pitch is reflected in its halfway line (x -> -x): what a horizontally flipped
#: image shows, seen by a camera on the same touchline. Left and right swap; top and bottom stay;
#: a left goal's post at y = +3.66 ("post left") becomes the right goal's post at y = +3.66
#: ("post right"). Unlike :data:`MIRROR` (a rotation of the pitch) this is a reflection.
FLIP_X: dict[str, str] = {
    "Side line top": "Side line top",
    "Side line bottom": "Side line bottom",
    "Side line left": "Side line right",
    "Side line right": "Side line left",
    "Middle line": "Middle line",
    "Circle left": "Circle right",
    "Circle central": "Circle central",
    "Circle right": "Circle left",
    "Big rect. left top": "Big rect. right top",
    "Big rect. left bottom": "Big rect. right bottom",
    "Big rect. left main": "Big rect. right main",
    "Big rect. right top": "Big rect. left top",
    "Big rect. right bottom": "Big rect. left bottom",
    "Big rect. right main": "Big rect. left main",
    "Small rect. left top": "Small rect. right top",
    "Small rect. left bottom": "Small rect. right bottom",
    "Small rect. left main": "Small rect. right main",
    "Small rect. right top": "Small rect. left top",
    "Small rect. right bottom": "Small rect. left bottom",
    "Small rect. right main": "Small rect. left main",
    "Goal left crossbar": "Goal right crossbar",
    "Goal right crossbar": "Goal left crossbar",
    "Goal unknown": "Goal unknown",
    "Line unknown": "Line unknown",
    "Goal left post left ": "Goal right post right",
    "Goal left post right": "Goal right post left",
    "Goal right post left": "Goal left post right",
    "Goal right post right": "Goal left post left ",
}

_BY_STRIPPED = {name.strip(): name for name in ALL_CLASSES}


def canonical_class_name(name: str) -> str | None:
    """The evaluator's spelling of ``name`` (trailing-space goal post fixed), or None if unknown."""
    if not isinstance(name, str):
        return None
    return _BY_STRIPPED.get(name.strip())


def close_class_names(name: str, n: int = 3) -> list[str]:
    """Up to ``n`` known class names that look like ``name`` (for error messages)."""
    lowered = {c.strip().lower(): c for c in ALL_CLASSES}
    hits = difflib.get_close_matches(str(name).strip().lower(), list(lowered), n=n, cutoff=0.5)
    return [lowered[h] for h in hits]
