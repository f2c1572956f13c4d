"""The classes of failure of benchmarks/misses.py: each rule on the inputs it reads."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from misses import frame_class  # noqa: E402


def _frame(classes, n_keypoints=10, off=None, accuracy=0.8, mirrored=False, ok=True, code=None):
    obs = SimpleNamespace(lines={c: None for c in classes if not c.startswith("Circle")},
                          circles={c: None for c in classes if c.startswith("Circle")}, n_keypoints=n_keypoints)
    result = SimpleNamespace(ok=ok, failure_code=code)
    matching = SimpleNamespace(mirrored=mirrored, class_status=lambda t: {**{c: "tp" for c in classes}, **(off or {})})
    score = SimpleNamespace(matching=lambda t: matching, accuracy=lambda t: accuracy)
    return obs, result, score


def test_each_frame_falls_in_the_first_class_whose_rule_holds():
    box = ["Big rect. left main", "Side line top"]
    assert frame_class(*_frame(box, ok=False, code="too_few_keypoints"))[0] == "no camera (too_few_keypoints)"
    assert frame_class(*_frame(box, accuracy=1.0)) == ("", [])  # perfect: no class
    central = frame_class(*_frame(["Middle line", "Circle central", "Side line top"], off={"Side line bottom": "fp"}))
    assert central == ("central view", ["Side line bottom: fp"])
    assert frame_class(*_frame(box, n_keypoints=5, off={"Side line top": "far"}))[0] == "few keypoints"
    assert frame_class(*_frame(box, off={"Big rect. left main": "far"}))[0] == "an observed class is off"
    assert frame_class(*_frame(box, off={"Goal left crossbar": "far"}))[0] == "an unseen class is off"
    # compared under the mirrored labels, an observed class is named as the evaluator named it
    assert frame_class(*_frame(box, off={"Big rect. right main": "far"}, mirrored=True))[0] == "an observed class is off"
    assert frame_class(*_frame(box, off={"Big rect. right main": "far"}))[0] == "an unseen class is off"
