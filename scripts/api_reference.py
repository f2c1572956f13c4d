"""Write docs/api.md, the Python API's reference, from the docstrings of what ``pnlviz`` exports.

    python scripts/api_reference.py [--check]

``--check``: exit 1 if docs/api.md is not what this script would write (the tests run it so)."""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "docs" / "api.md"
CAMERA_METHODS = ("from_look_at", "from_soccernet", "to_soccernet", "project", "project_with_depth", "pitch_to_image",
                  "image_to_pitch", "homography", "scaled", "in_image", "allclose")


def _entry(name: str, obj, level: str = "###") -> list[str]:
    try:
        sig = str(inspect.signature(obj))
    except (TypeError, ValueError):
        sig = ""
    doc = inspect.cleandoc(obj.__doc__ or "").strip()
    return [f"{level} `{name}{sig}`", "", doc, ""]


def reference() -> str:
    import pnlviz

    lines = ["# The Python API", "",
             "Written by `python scripts/api_reference.py` from the docstrings (do not edit by hand). "
             "Everything here is imported by `import pnlviz`; the rest of the package is private. "
             "Every entry has an example; the tests run them all, as they are written here, after "
             "`import numpy as np`, `import pnlviz` and `from pnlviz import Camera`.", ""]
    lines += [inspect.cleandoc(pnlviz.api.__doc__).split(">>>")[0].strip(), ""]
    for name in sorted(n for n in pnlviz.__all__ if not n.isupper()):
        obj = getattr(pnlviz, name)
        if name == "detect":
            obj = pnlviz.api.detect
        lines += _entry(f"pnlviz.{name}", obj, "##")
        if name == "Camera":
            for method in CAMERA_METHODS:
                lines += _entry(f"Camera.{method}", getattr(pnlviz.Camera, method))
    return "\n".join(lines).rstrip() + "\n"


def main() -> int:
    text = reference()
    if "--check" in sys.argv[1:]:
        if not OUT.exists() or OUT.read_text() != text:
            print(f"{OUT} is out of date: run python scripts/api_reference.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
