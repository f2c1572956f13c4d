import contextlib
from pathlib import Path

import pytest

from helpers import running_app

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the repository (CI has it); tests that need it skip without it."""
    if not (SHARED / "data").is_dir():
        pytest.skip(f"{SHARED} not found: real-data tests need ../shared beside the repo")
    return SHARED


@pytest.fixture()
def serve():
    """Start the app: ``serve(data, **options)`` (see ``helpers.running_app``) gives a running
    ``PnlvizApp`` on a free port; every app started is stopped at the end of the test."""
    with contextlib.ExitStack() as stack:
        yield lambda data, **options: stack.enter_context(running_app(data, **options))
