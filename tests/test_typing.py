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
