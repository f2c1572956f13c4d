import contextlib
import signal
import threading
from pathlib import Path

import pytest

from helpers import running_app

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
#: why a real-data test did not run: one reason for all of them, so pytest's summary says it on one line
SHARED_MISSING = (f"{SHARED} not found: the real-data tests need ../shared beside the repository "
                  "(CI stops without it)")


#: where the reason is written (the line pytest's summary shows for those skips)
_REASON_LINE = next(i for i, line in enumerate(Path(__file__).read_text().splitlines(), 1)
                    if line.startswith("SHARED_MISSING"))


def shared_found() -> bool:
    return (SHARED / "data").is_dir() and (SHARED / "reference").is_dir()


def pytest_report_header(config) -> str:
    return f"../shared: {SHARED}" if shared_found() else f"../shared: MISSING, {SHARED_MISSING}"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the repository (CI has it); a test that needs it skips without it,
    every such skip with the same one-line reason (:data:`SHARED_MISSING`)."""
    if not shared_found():
        pytest.skip(SHARED_MISSING)
    return SHARED


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """The skips for a missing ../shared are reported at one place, so that pytest's summary
    folds them into one line ("SKIPPED [N] ... ../shared not found ...")."""
    outcome = yield
    report = outcome.get_result()
    longrepr = report.longrepr
    if report.skipped and isinstance(longrepr, tuple) and str(longrepr[2]).endswith(SHARED_MISSING):
        report.longrepr = (__file__, _REASON_LINE, longrepr[2])


@pytest.fixture(scope="session")
def evaluator():
    """The official SoccerNet evaluator's helpers (``SoccerNet.Evaluation.utils_calibration``), the
    oracle of the metric tests; a test that needs it skips where it is not installed."""
    return pytest.importorskip("SoccerNet.Evaluation.utils_calibration")


@pytest.fixture()
def serve():
    """Start the app: ``serve(data, **options)`` (see ``helpers.running_app``) gives a running
    ``PnlvizApp`` on a free port; every app started is stopped at the end of the test."""
    with contextlib.ExitStack() as stack:
        yield lambda data, **options: stack.enter_context(running_app(data, **options))


# ----------------------------------------------------------------------------- Ctrl+C
# The command line's main() turns a KeyboardInterrupt into exit code 130 (and tests hold that), so
# a Ctrl+C that lands while a test runs a command in-process would be taken for the command's and
# the session would go on to the next test. A Ctrl+C is noted here as it arrives; the test it
# lands in ends the session.
_CTRL_C = {"pressed": False}


def _note_ctrl_c(signum, frame):
    _CTRL_C["pressed"] = True
    signal.default_int_handler(signum, frame)


def pytest_sessionstart(session):
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _note_ctrl_c)


@pytest.hookimpl(trylast=True)
def pytest_runtest_logreport(report):
    if _CTRL_C["pressed"] and report.when == "teardown":
        pytest.exit("Ctrl+C: the session stops (a command run in-process had taken it for its own)", returncode=130)
