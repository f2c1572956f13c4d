"""The package type-checks: ``mypy`` (pinned in the dev extra, configured in pyproject.toml's
``[tool.mypy]``) reports no error on ``pnlviz``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_mypy_reports_no_error_on_the_package(request):
    # a missing mypy fails here (it is in the dev extra): the check must not pass by being skipped
    import mypy  # noqa: F401

    # the cache lives in pytest's own (ignored by git, kept between runs: about a minute cold,
    # seconds warm); -p no:cacheprovider gives a fresh one under the temporary folder
    store = getattr(request.config, "cache", None)
    cache = store.mkdir("mypy") if store is not None else request.getfixturevalue(
        "tmp_path_factory").mktemp("mypy_cache")
    run = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", str(cache)], cwd=REPO,
                         capture_output=True, text=True)
    assert run.returncode == 0, f"mypy pnlviz:\n{run.stdout}{run.stderr}"
    assert "Success: no issues found" in run.stdout


#: a downstream script: what a tracker's code does with the API, typed as its users type it
DOWNSTREAM = '''
import numpy as np
import pnlviz
from pnlviz.api import detect

cam = pnlviz.Camera.from_look_at((0.0, 50.0, -20.0), (0.0, 0.0, 0.0), hfov_deg=40, width=960, height=540)
pixels: np.ndarray = cam.project([[0.0, 0.0, 0.0], [10.0, 5.0, 0.0]])
ground: np.ndarray = cam.image_to_pitch([[480.0, 300.0]])
again: np.ndarray = cam.pitch_to_image(ground)
same: bool = cam.allclose(pnlviz.Camera.from_soccernet(cam.to_soccernet(), image_size=(960, 540)))
view: np.ndarray = pnlviz.top_view(cam, points_pitch=[[1.0, 2.0]], points_image=pixels)
ds = pnlviz.open_dataset(pnlviz.SAMPLE_DIR)
stems: list[str] = list(ds.stems)
found = detect(np.zeros((540, 960, 3), np.uint8))
result = pnlviz.calibrate(**found, image_size=(960, 540))
'''


def _mypy_strict(code: str, tmp_path: Path, request) -> subprocess.CompletedProcess:
    """``mypy --strict`` on ``code`` as a user's script, against this checkout's package (its own
    errors are its test's business: imports followed silently)."""
    import os

    script = tmp_path / "downstream.py"
    script.write_text(code)
    store = getattr(request.config, "cache", None)
    cache = store.mkdir("mypy-downstream") if store is not None else tmp_path / "cache"
    return subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent", "--cache-dir",
                           str(cache), str(script)], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "MYPYPATH": str(REPO)})


def api_page_script() -> str:
    """Every example of docs/api.md as one script a user could write: each entry's examples in a
    function of their own (names are reused from one entry to the next), after the imports the
    page names."""
    import doctest
    import re
    import textwrap

    page = (REPO / "docs" / "api.md").read_text()
    sections = re.split(r"^(#{2,3} `[^`]+`)$", page, flags=re.M)[1:]
    lines = ["import numpy as np", "import pnlviz", "from pnlviz import Camera", ""]
    for i, body in enumerate(sections[1::2]):
        lines.append(f"def entry_{i}() -> None:")
        lines += [textwrap.indent(e.source.rstrip("\n"), "    ") for e in doctest.DocTestParser().get_examples(body)]
        lines += ["    pass", ""]
    return "\n".join(lines) + "\n"


def test_a_downstream_script_and_the_readme_example_type_check_strictly(tmp_path, request):
    import re

    readme = (REPO / "README.md").read_text()
    example = re.search(r"```python\n(.*?)```", readme, re.S).group(1)
    page = api_page_script()
    assert page.count("def entry_") >= 20
    for code in (example, DOWNSTREAM, page):
        run = _mypy_strict(code, tmp_path, request)
        assert run.returncode == 0, f"{run.stdout}{run.stderr}\n{code}"
    # and the API's types are real ones, not Any: a wrong use is caught
    run = _mypy_strict("import pnlviz\nn: int = pnlviz.open_dataset('x')\nm: str = pnlviz.keypoints()\n", tmp_path, request)
    assert run.returncode == 1 and run.stdout.count("error: Incompatible types in assignment") == 2, run.stdout
