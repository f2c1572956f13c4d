"""pnlviz outside its checkout: the wheel built from the repository, installed without PyTorch into
a fresh virtual environment, runs every kind of command from another directory (its pitch model,
light model and sample come with it) and the README's Python example; with PyTorch added
(``[detect]``), ``pnlviz detect`` runs too.

Slow (a virtual environment gets numpy, scipy, OpenCV and viser from the package registry or
pip's cache: about 1.5 minutes), so one environment serves the whole module."""

import os
import re
import shutil
import subprocess
import sys
import urllib.request
import zipfile
from pathlib import Path

import pytest

from helpers import free_port

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git lists the repository's files")


def _run(cmd, cwd, env, timeout=600):
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """``(venv bin folder, a working folder elsewhere, environment)``: the wheel built from the
    repository's tracked files (a copy, so that the build writes nothing into the checkout),
    installed into a fresh virtual environment."""
    root = tmp_path_factory.mktemp("wheel")
    src = root / "src"
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        path = REPO / name
        if not path.exists() and not path.is_symlink():
            continue  # deleted in the work tree
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        if path.is_symlink():
            (src / name).symlink_to(os.readlink(path))
        elif path.is_file():
            shutil.copy2(path, src / name)
    built = _run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(root / "dist"), "."],
                 src, os.environ)
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    wheel = next((root / "dist").glob("pnlviz-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert "pnlviz/_assets/field_model/soccer_pitch.json" in names and "pnlviz/_assets/models/light.pt" in names
    assert "pnlviz/_sample/00000.jpg" in names and "pnlviz/py.typed" in names
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(XDG_STATE_HOME=str(root / "state"), OMP_NUM_THREADS="1")
    pip = _run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)], root, env, timeout=1500)
    assert pip.returncode == 0, pip.stderr[-3000:]
    work = root / "elsewhere"
    work.mkdir()
    return venv / "bin", work, env


def test_the_wheel_runs_without_torch_from_anywhere(installed):
    bin_dir, work, env = installed
    python = str(bin_dir / "python")
    assert _run([python, "-c", "import torch"], work, env).returncode != 0  # the base install has no torch
    where = _run([python, "-c", "import pnlviz; print(pnlviz.ASSETS_DIR, pnlviz.SAMPLE_DIR)"], work, env)
    assert "site-packages" in where.stdout and str(REPO) not in where.stdout
    shutil.copytree(REPO / "examples" / "sample", work / "d")
    cal = _run([str(bin_dir / "pnlviz"), "calibrate", "--data", "d", "--out", "cams.zip"], work, env)
    assert cal.returncode == 0 and "calibrated" in cal.stdout, cal.stderr
    assert len(zipfile.ZipFile(work / "cams.zip").namelist()) >= 30
    exp = _run([str(bin_dir / "pnlviz"), "export", "--all", "--out", "labels.zip"], work, env)
    assert exp.returncode == 0 and "exported" in exp.stdout, exp.stderr
    det = _run([str(bin_dir / "pnlviz"), "detect", "--data", "d", "--out", "p.zip"], work, env)
    assert det.returncode == 2 and "pip install 'pnlviz[detect]'" in det.stderr and "Traceback" not in det.stderr


def test_the_installed_app_serves_the_bundled_sample(installed):
    bin_dir, work, env = installed
    port = free_port()
    proc = subprocess.Popen([str(bin_dir / "pnlviz"), "serve", "--port", str(port)], cwd=work, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        said = []
        while proc.poll() is None and not any("pnlviz: open" in line for line in said):
            said.append(proc.stdout.readline())  # serve says where it is before it takes Ctrl+C or a kill
        page = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=60).read()
        assert b"<html" in page.lower()
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=60)
    out = "".join(said) + out
    assert "no background detection" in err and "pnlviz[detect]" in err  # says how the app runs without torch
    assert "_sample (" in out and str(Path(env["XDG_STATE_HOME"]) / "pnlviz" / "sample.edits") in out


def test_the_readme_python_example_runs_installed(installed):
    bin_dir, work, env = installed
    readme = (REPO / "README.md").read_text()
    code = re.search(r"## Python API\s+```python\n(.*?)```", readme, re.S).group(1)
    run = _run([str(bin_dir / "python"), "-c", code], work, env)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (work / "top_view.png").stat().st_size > 10_000
    x, y = (float(v) for v in re.findall(r"-?\d+\.\d+", run.stdout.splitlines()[-1]))
    assert -52.5 <= x <= 52.5 and -34 <= y <= 34  # the player stands on the pitch


def test_with_the_detect_extra_pnlviz_detect_runs(installed):
    bin_dir, work, env = installed
    pip = _run([str(bin_dir / "python"), "-m", "pip", "install", "-q", "torch==2.13.0"], work, env, timeout=1500)
    if pip.returncode != 0:
        pytest.skip(f"torch==2.13.0 could not be installed here: {pip.stderr.strip()[-300:]}")
    if not (work / "d").exists():
        shutil.copytree(REPO / "examples" / "sample", work / "d")
    det = _run([str(bin_dir / "pnlviz"), "detect", "--data", "d", "--out", "p.zip"], work, env, timeout=900)
    assert det.returncode == 0, det.stderr[-2000:]
    images = len(list((work / "d").glob("*.jpg")))
    assert len(zipfile.ZipFile(work / "p.zip").namelist()) == images > 20
