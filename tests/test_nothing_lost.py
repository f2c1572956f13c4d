"""Nothing overwritten, nothing read as the wrong thing (issue #32): no command writes over or
under what it reads; an edits folder belongs to the dataset it was made for; ``--edits`` that is
not an edits folder is an error, never "no edits"."""

import hashlib
import os
import shutil

import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main


def _tree(root):
    """Every file under ``root`` with a digest of its bytes."""
    return {str(p.relative_to(root)): hashlib.sha1(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _frames(dst, pairs):
    """Frames of the bundled sample copied as ``dst/<name>`` (``pairs``: (sample stem, name))."""
    dst.mkdir(parents=True)
    for src, name in pairs:
        for ext in (".jpg", ".json"):
            shutil.copy(EXAMPLES_DIR / "sample" / f"{src}{ext}", dst / f"{name}{ext}")
    return dst


@pytest.mark.parametrize("inner", ["annotations", "keypoints"])
def test_export_never_writes_over_or_under_its_own_dataset(tmp_path, capsys, inner):
    """``export --data X/annotations --out X --all`` used to replace all 6 of X's annotation files
    with its own (``X/keypoints`` with label files): refused before any work, one line naming both
    paths, every file of X as it was."""
    x = tmp_path / "X"
    _frames(x / inner, [(f"0000{i}", f"0000{i}") for i in range(6)])
    before = _tree(tmp_path)
    assert main(["export", "--data", str(x / inner), "--out", str(x), "--all", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(x) in err[0] and str(x / inner) in err[0] and "holds the dataset" in err[0]
    # and inside it
    assert main(["export", "--data", str(x / inner), "--out", str(x / inner / "out"), "--all", "--no-progress"]) == 2
    assert "inside the dataset" in capsys.readouterr().err
    assert _tree(tmp_path) == before


def test_labels_refuse_an_output_folder_above_their_dataset(tmp_path, capsys):
    x = tmp_path / "X"
    data = _frames(x / "data", [("00000", "00000"), ("00001", "00001")])
    before = _tree(tmp_path)
    assert main(["labels", "--data", str(data), "--out", str(x)]) == 2
    assert "holds the dataset" in capsys.readouterr().err
    assert _tree(tmp_path) == before


@pytest.fixture()
def two_datasets(tmp_path):
    """Datasets A and B with the same stems but other pictures, and A's edits folder (a review
    and a moved point, written by the app)."""
    from pnlviz.app.state import AppState

    a = _frames(tmp_path / "A", [("00000", "00000"), ("00001", "00001"), ("00002", "00002")])
    b = _frames(tmp_path / "B", [("00003", "00000"), ("00004", "00001"), ("00005", "00002")])
    st = AppState(a, edits=tmp_path / "A.edits")
    try:
        st.set_review("00000", "accepted")
        st.move_keypoint("00001", 5, 100.0, 100.0)
    finally:
        st.close()
    return a, b, tmp_path / "A.edits"


def test_an_edits_folder_of_another_dataset_is_refused_and_can_be_adopted(two_datasets, tmp_path, capsys):
    """A's edits used to be exported as reviewed labels of B's pictures (same stems). Now export,
    qa, calibrate and the app refuse them with the mismatches listed; --force-edits adopts the
    folder; A with its own folder goes on as before."""
    from pnlviz.app.state import AppState
    from pnlviz.data.edits import EditsFolderError

    a, b, edits = two_datasets
    before = _tree(edits)
    out = tmp_path / "out"
    assert main(["export", "--data", str(b), "--edits", str(edits), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "holds edits of another dataset" in err and "00000" in err and "00001" in err and str(a) in err
    assert not out.exists()
    assert main(["qa", "--data", str(b), "--edits", str(edits), "--out", str(tmp_path / "q.jsonl"),
                 "--no-progress"]) == 2
    assert main(["calibrate", "--data", str(b), "--edits", str(edits), "--out", str(tmp_path / "c.zip"),
                 "--no-progress"]) == 2
    assert "another dataset" in capsys.readouterr().err
    with pytest.raises(EditsFolderError, match="another dataset"):
        AppState(b, edits=edits)
    assert _tree(edits) == before  # refused: nothing read into B, nothing changed in the folder
    assert main(["export", "--data", str(b), "--edits", str(edits), "--out", str(out), "--no-progress",
                 "--force-edits"]) == 0
    assert "adopted with --force-edits" in capsys.readouterr().err
    assert main(["export", "--data", str(a), "--edits", str(edits), "--out", str(tmp_path / "a_out"),
                 "--no-progress"]) == 0
    assert sorted(p.stem for p in (tmp_path / "a_out" / "annotations").glob("*.json")) == ["00000", "00001"]


@pytest.mark.parametrize("kind", ["typo", "file", "fifo", "dev_zero", "empty_folder"])
def test_edits_that_is_not_an_edits_folder_is_an_error(two_datasets, tmp_path, capsys, kind):
    """``--edits`` that is a typo, a file, a FIFO, /dev/zero or a folder without edits used to
    read as "no edits" (export exit 0): now every command that reads one says what it is, writes
    nothing and exits non-zero."""
    a, _, _ = two_datasets
    path = tmp_path / "edits_arg"
    if kind == "file":
        path.write_text("{}")
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev_zero":
        path = "/dev/zero"
    elif kind == "empty_folder":
        path.mkdir()
    for command, out in (("export", tmp_path / "e_out"), ("qa", tmp_path / "q.jsonl"),
                         ("calibrate", tmp_path / "c.zip")):
        code = main([command, "--data", str(a), "--edits", str(path), "--out", str(out), "--no-progress"])
        err = capsys.readouterr().err
        assert code != 0 and f"--edits {path}" in err, (command, err)
        assert not os.path.exists(out)
