from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the repository (CI has it); tests that need it skip without it."""
    if not (SHARED / "data").is_dir():
        pytest.skip(f"{SHARED} not found: real-data tests need ../shared beside the repo")
    return SHARED
