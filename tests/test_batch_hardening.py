"""Batch commands against bad input: damaged zip members, file names that are not UTF-8, outputs
written as they are computed, outputs over inputs, nothing to do, duplicate stems, the dataset's
cameras, oversized files and images. Every bad input is one line; the batch goes on."""

from __future__ import annotations

import json
import os
import shutil
import struct
import time
import zipfile
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from pnlviz import EXAMPLES_DIR
from pnlviz.cli import main
from pnlviz.data import DataError, decode_image, open_dataset, read_camera_zip, read_predictions, write_camera_zip

SAMPLE = EXAMPLES_DIR / "sample"
STEMS = ("00000", "00001", "00002")
BAD = b"\xff"  # a file name byte that is not UTF-8


def copy_frames(dest: Path, stems=STEMS, images: bool = True, cameras: bool = False) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    for stem in stems:
        shutil.copy(SAMPLE / f"{stem}.json", dest / f"{stem}.json")
        if images:
            shutil.copy(SAMPLE / f"{stem}.jpg", dest / f"{stem}.jpg")
        if cameras:
            (dest / "cameras").mkdir(exist_ok=True)
            shutil.copy(SAMPLE / "cameras" / f"camera_{stem}.json", dest / "cameras" / f"camera_{stem}.json")
    return dest


def zip_frames(zpath: Path, stems=STEMS, images: bool = False) -> Path:
    with zipfile.ZipFile(zpath, "w", zipfile.ZIP_DEFLATED) as zf:
        for stem in stems:
            zf.write(SAMPLE / f"{stem}.json", f"{stem}.json")
            if images:
                zf.write(SAMPLE / f"{stem}.jpg", f"{stem}.jpg")
    return zpath


def bad_name(folder: Path, name: bytes) -> bytes:
    """The bytes path ``folder/name`` (a name that is not valid UTF-8)."""
    return os.path.join(os.fsencode(folder), name)


def _central_entries(data: bytes, member: str):
    """Offsets of the central-directory records of ``member``."""
    name = member.encode()
    pos = data.find(b"PK\x01\x02")
    while pos >= 0:
        n = struct.unpack_from("<H", data, pos + 28)[0]
        if data[pos + 46:pos + 46 + n] == name:
            yield pos
        pos = data.find(b"PK\x01\x02", pos + 4)


def patch_zip(zpath: Path, member: str, *, size: int | None = None, flags: int | None = None,
              method: int | None = None, first_byte: int | None = None) -> None:
    """Patch the headers (declared size, flags, compression method) or the first compressed byte
    of one member, in place."""
    with zipfile.ZipFile(zpath) as zf:
        info = zf.getinfo(member)
    data = bytearray(zpath.read_bytes())
    local = info.header_offset
    for pos, (size_at, flags_at, method_at) in [(local, (22, 6, 8))] + [(p, (24, 8, 10)) for p in _central_entries(data, member)]:
        if size is not None:
            struct.pack_into("<I", data, pos + size_at, size)
        if flags is not None:
            struct.pack_into("<H", data, pos + flags_at, flags)
        if method is not None:
            struct.pack_into("<H", data, pos + method_at, method)
    if first_byte is not None:
        n, m = struct.unpack_from("<HH", data, local + 26)
        data[local + 30 + n + m] = first_byte
    zpath.write_bytes(bytes(data))


def corrupt_deflate(zpath: Path, member: str) -> None:
    """BFINAL=1, BTYPE=11 (reserved): zlib stops at once with 'invalid block type'."""
    patch_zip(zpath, member, first_byte=0xFF)


def one_line(err: str, *needles: str) -> str:
    lines = [line for line in err.splitlines() if all(n in line for n in needles)]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def png_header_only(path: Path, width: int, height: int) -> None:
    """A valid PNG header (IHDR with a right CRC) claiming ``width`` x ``height``, tiny body."""
    ok, buf = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))
    data = bytearray(buf.tobytes())
    struct.pack_into(">II", data, 16, width, height)
    struct.pack_into(">I", data, 29, zlib.crc32(bytes(data[12:29])))
    path.write_bytes(bytes(data))


# ------------------------------------------------------------------------- 1. damaged zip members
@pytest.mark.parametrize("damage, needle", [
    (dict(first_byte=0xFF), "invalid block type"),
    (dict(flags=0x1), "encrypted"),
    (dict(method=9), "compression"),
])
def test_every_zip_member_failure_is_one_data_error(tmp_path, damage, needle):
    from pnlviz.data.reading import read_zip_member
    z = zip_frames(tmp_path / "d.zip")
    patch_zip(z, "00001.json", **damage)
    with zipfile.ZipFile(z) as zf:
        with pytest.raises(DataError) as ei:
            read_zip_member(zf, "00001.json", f"{z}:00001.json")
        assert str(ei.value).startswith(f"{z}:00001.json: cannot read zip member") and needle in str(ei.value)
        with pytest.raises(DataError, match="no item named"):
            read_zip_member(zf, "nope.json", "x")
        assert read_zip_member(zf, "00000.json", "x") == (SAMPLE / "00000.json").read_bytes()
    ds = open_dataset(z)
    with pytest.raises(DataError, match="cannot read zip member"):
        ds.annotation("00001")
    assert ds.annotation("00002")


def test_bad_crc_member(tmp_path):
    z = zip_frames(tmp_path / "d.zip")
    with zipfile.ZipFile(z) as zf:
        info = zf.getinfo("00001.json")
    data = bytearray(z.read_bytes())
    for pos in [info.header_offset + 14] + [p + 16 for p in _central_entries(data, "00001.json")]:
        data[pos] ^= 0xFF  # the CRC-32 fields
    z.write_bytes(bytes(data))
    with pytest.raises(DataError, match="00001.json: cannot read zip member: Bad CRC"):
        open_dataset(z).annotation("00001")


def test_validate_calibrate_eval_sheet_go_on_past_a_corrupt_member(tmp_path, capsys):
    gt = zip_frames(tmp_path / "gt.zip", images=True)
    corrupt_deflate(gt, "00001.json")
    assert main(["validate", "--data", str(gt)]) == 1
    one_line(capsys.readouterr().err, "00001.json", "cannot read zip member")

    cams = tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(gt), "--out", str(cams), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert "calibrated 2/3 frames" in out
    one_line(err, "00001.json", "cannot read zip member")

    shutil.copy(cams, tmp_path / "cams_bad.zip")
    corrupt_deflate(tmp_path / "cams_bad.zip", "camera_00002.json")
    assert main(["eval", "--gt", str(gt), "--pred", str(tmp_path / "cams_bad.zip"), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    one_line(err, "camera_00002.json", "cannot read zip member")
    one_line(err, "00001.json", "cannot read zip member")
    assert "frames 2, calibrated 1" in out

    sheet = tmp_path / "sheet.png"
    assert main(["sheet", "--data", str(gt), "--out", str(sheet), "--cameras", str(tmp_path / "cams_bad.zip")]) == 0
    one_line(capsys.readouterr().err, "camera_00002.json", "cannot read zip member")
    assert cv2.imread(str(sheet)) is not None


def test_corrupt_member_in_a_prediction_zip(tmp_path):
    from pnlviz.data import Predictions, write_predictions

    z = tmp_path / "p.zip"
    write_predictions(z, {s: Predictions(keypoints={1: (0.5, 0.5, 0.9)}) for s in STEMS})
    corrupt_deflate(z, "00001.json")
    with pytest.raises(DataError, match="00001.json: cannot read zip member"):
        read_predictions(z)
    seen = []
    assert list(read_predictions(z, on_error=seen.append)) == ["00000", "00002"]
    assert len(seen) == 1 and "00001.json" in str(seen[0])


def test_invalid_utf8_member_name_in_a_flagged_zip_is_one_line(tmp_path):
    z = tmp_path / "d.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("é.json", "{}")  # non-ASCII: stored with the UTF-8 flag
    z.write_bytes(z.read_bytes().replace("é".encode(), b"\xff\xfe"))
    with pytest.raises(DataError, match="not valid UTF-8"):
        open_dataset(z)


# ------------------------------------------------------------------- 2. names that are not UTF-8
@pytest.fixture()
def frames_with_bad_name(tmp_path):
    d = copy_frames(tmp_path / "d")
    shutil.copy(SAMPLE / "00003.json", bad_name(d, BAD + b".json"))
    shutil.copy(SAMPLE / "00003.jpg", bad_name(d, BAD + b".jpg"))
    return d


def test_dataset_rejects_names_that_are_not_utf8(frames_with_bad_name):
    ds = open_dataset(frames_with_bad_name)
    assert ds.stems == STEMS
    assert len(ds.rejected) == 2
    for err in ds.rejected:
        assert "\\xff" in str(err) and "not valid UTF-8" in str(err)
        str(err).encode("utf-8")  # printable


def test_calibrate_eval_csv_sheet_with_a_name_that_is_not_utf8(frames_with_bad_name, tmp_path, capsys):
    d = frames_with_bad_name
    cams = tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(d), "--out", str(cams), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert "calibrated 3/3 frames" in out and err.count("not valid UTF-8") == 2
    assert zipfile.ZipFile(cams).namelist() == [f"camera_{s}.json" for s in STEMS]

    csv = tmp_path / "frames.csv"
    assert main(["eval", "--gt", str(d), "--pred", str(cams), "--csv", str(csv), "--no-progress"]) == 0
    assert csv.read_text().count("\n") == 4
    sheet = tmp_path / "sheet.png"
    assert main(["sheet", "--data", str(d), "--out", str(sheet)]) == 0  # used to segfault in OpenCV
    assert cv2.imread(str(sheet)).shape[1] == 4 * 480 + 5 * 4
    odd = bad_name(tmp_path, BAD + b"sheet.png")
    assert main(["sheet", "--data", str(d), "--out", os.fsdecode(odd)]) == 0
    assert os.path.getsize(odd) > 1000


def test_opencv_text_never_sees_surrogates():
    from pnlviz.viz import caption, class_colour, cv_text, draw_annotation

    img = np.zeros((60, 200, 3), np.uint8)
    caption(img, "frame \udcff é")  # segfaulted in cv2.getTextSize
    assert cv_text("a\udcffé") == "a??"
    draw_annotation(img, {"Middle \udcff": np.array([[0.1, 0.1], [0.5, 0.5]])}, labels=True)
    assert len(class_colour("x\ud800")) == 3


def test_prediction_and_camera_folders_reject_names_that_are_not_utf8(tmp_path):
    from pnlviz.data import Predictions, write_predictions
    from pnlviz.data.cameras import read_cameras

    z = tmp_path / "p.zip"
    write_predictions(z, {"1": Predictions(keypoints={1: (0.5, 0.5, 0.9)})})
    folder = tmp_path / "preds"
    folder.mkdir()
    zipfile.ZipFile(z).extractall(folder)
    shutil.copy(folder / "1.json", bad_name(folder, BAD + b".json"))
    seen = []
    assert list(read_predictions(folder, on_error=seen.append)) == ["1"]
    assert len(seen) == 1 and "not valid UTF-8" in str(seen[0])
    with pytest.raises(DataError, match="not valid UTF-8"):
        read_predictions(folder)

    cams = tmp_path / "cams"
    cams.mkdir()
    shutil.copy(SAMPLE / "cameras" / "camera_00000.json", cams / "camera_00000.json")
    shutil.copy(SAMPLE / "cameras" / "camera_00000.json", bad_name(cams, b"camera_" + BAD + b".json"))
    got, problems = read_cameras(cams)
    assert list(got) == ["00000"] and len(problems) == 1 and "not valid UTF-8" in problems[0]


# ------------------------------------------------------------------------ 3. streaming outputs
def test_zip_stream_writes_as_it_goes_and_orders_at_close(tmp_path, monkeypatch):
    from pnlviz.data import ZipStream
    from pnlviz.data.cameras import camera_member, camera_zip_order

    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)  # zip timestamps: the same for both
    cams = {s: json.loads((SAMPLE / "cameras" / f"camera_0000{s[-1]}.json").read_text()) for s in ("2", "10", "1")}
    reference = tmp_path / "ref.zip"
    write_camera_zip(reference, cams)

    out = tmp_path / "out.zip"
    with ZipStream(out, key=camera_zip_order) as zs:
        for stem, cam in cams.items():  # 2, 10, 1: out of order
            zs.add(*camera_member(stem, cam, out))
            assert not out.exists()  # nothing under the final name before the end
        with pytest.raises(DataError, match="not valid UTF-8"):
            zs.add("camera_\udcff.json", "{}")
        with pytest.raises(DataError, match="twice"):
            zs.add("camera_1.json", "{}")
    assert out.read_bytes() == reference.read_bytes()
    assert sorted(os.listdir(tmp_path)) == ["out.zip", "ref.zip"]  # no temporary file left


def test_zip_stream_keeps_what_was_written_on_an_exception_or_discards_it(tmp_path):
    from pnlviz.data import ZipStream
    out = tmp_path / "o.zip"
    with pytest.raises(KeyboardInterrupt), ZipStream(out) as zs:
        zs.add("a.json", "{}")
        raise KeyboardInterrupt
    assert zipfile.ZipFile(out).namelist() == ["a.json"]
    with pytest.raises(RuntimeError), ZipStream(out, keep_partial=False) as zs:
        zs.add("b.json", "{}")
        raise RuntimeError("boom")
    assert zipfile.ZipFile(out).namelist() == ["a.json"] and os.listdir(tmp_path) == ["o.zip"]
    # a run that fails before its first result leaves the path as it was: no empty zip, no journal
    fresh = tmp_path / "fresh.zip"
    with pytest.raises(SystemExit), ZipStream(fresh, journal=True):
        raise SystemExit("error: cannot connect")
    assert not fresh.exists() and os.listdir(tmp_path) == ["o.zip"]
    with pytest.raises(SystemExit), ZipStream(out, journal=True):
        raise SystemExit("error: cannot connect")
    assert zipfile.ZipFile(out).namelist() == ["a.json"] and os.listdir(tmp_path) == ["o.zip"]  # the old one kept
    with pytest.raises(DataError, match="is a folder"):
        ZipStream(tmp_path)


def test_line_stream_orders_lines_by_key(tmp_path):
    from pnlviz.data import LineStream
    out = tmp_path / "r.jsonl"
    with LineStream(out) as ls:
        for key in (2, 0, 1):
            ls.add(json.dumps({"k": key}), key=key)
        with pytest.raises(ValueError):
            ls.add("two\nlines")
    assert [json.loads(line)["k"] for line in out.read_text().splitlines()] == [0, 1, 2]


def test_calibrate_complete_run_writes_the_same_bytes_as_the_zip_writer(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)
    d = copy_frames(tmp_path / "d", stems=("00000", "00001", "00002", "00010"), images=False)
    out, report = tmp_path / "cams.zip", tmp_path / "r.jsonl"
    assert main(["calibrate", "--data", str(d), "--out", str(out), "--report", str(report), "--no-progress"]) == 0
    write_camera_zip(tmp_path / "ref.zip", read_camera_zip(out))
    assert out.read_bytes() == (tmp_path / "ref.zip").read_bytes()
    assert [json.loads(line)["stem"] for line in report.read_text().splitlines()] == ["00000", "00001", "00002", "00010"]


def test_calibrate_interrupted_keeps_the_frames_done(tmp_path, monkeypatch, capsys):
    import pnlviz.commands.calibrate as calib_cli

    d = copy_frames(tmp_path / "d", stems=("00000", "00001", "00002", "00003"), images=False)
    real = calib_cli.calibrate_stem

    def fake(ds, stem, *a):
        if stem == "00002":
            raise KeyboardInterrupt
        return real(ds, stem, *a)

    monkeypatch.setattr(calib_cli, "calibrate_stem", fake)
    out, report = tmp_path / "cams.zip", tmp_path / "r.jsonl"
    assert main(["calibrate", "--data", str(d), "--out", str(out), "--report", str(report), "--no-progress"]) == 130
    assert one_line(capsys.readouterr().err, "interrupted") == f"interrupted: kept 2 of 4 frames in {out}"
    assert zipfile.ZipFile(out).namelist() == ["camera_00000.json", "camera_00001.json"]
    assert len(report.read_text().splitlines()) == 2


def test_calibrate_a_camera_that_cannot_be_written_is_one_line(tmp_path, monkeypatch, capsys):
    import pnlviz.commands.calibrate as calib_cli

    d = copy_frames(tmp_path / "d", images=False)
    real = calib_cli.calibrate_stem

    def fake(ds, stem, *a):
        stem, cam, report = real(ds, stem, *a)
        if stem == "00001":
            cam = dict(cam, pan_degrees=float("nan"))
        return stem, cam, report

    monkeypatch.setattr(calib_cli, "calibrate_stem", fake)
    out = tmp_path / "cams.zip"
    assert main(["calibrate", "--data", str(d), "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr()
    assert "calibrated 2/3 frames" in text.out
    one_line(text.err, "camera_00001.json", "not finite")
    assert zipfile.ZipFile(out).namelist() == ["camera_00000.json", "camera_00002.json"]


# ---------------------------------------------------------------------- 4. outputs and inputs
def test_check_output(tmp_path):
    from pnlviz.data import OutputError, check_output
    d = copy_frames(tmp_path / "d", stems=("00000",), images=False)
    z = zip_frames(tmp_path / "d.zip", stems=("00000",))
    check_output(tmp_path / "out.zip", inputs=[None, z], datasets=[d, z, None])
    for out, kw, needle in [
        (d / "00000.json", dict(inputs=[d / "00000.json"]), "would overwrite the input"),
        (tmp_path / "x" / ".." / "d.zip", dict(inputs=[z]), "would overwrite the input"),
        (d / "preds.zip", dict(datasets=[d]), "inside the dataset folder"),
        (d / "new" / "deeper" / "x.csv", dict(datasets=[d]), "inside the dataset folder"),
        (d, dict(datasets=[d]), "would overwrite the dataset"),
        (z, dict(datasets=[z]), "would overwrite the dataset"),
    ]:
        with pytest.raises(OutputError, match=needle) as ei:
            check_output(out, what="--csv", **kw)
        assert str(ei.value).startswith("--csv ") and "\n" not in str(ei.value)
    (tmp_path / "link.json").symlink_to(d / "00000.json")
    with pytest.raises(OutputError):
        check_output(tmp_path / "link.json", inputs=[d / "00000.json"])


def test_commands_refuse_outputs_over_inputs_or_inside_the_dataset(tmp_path, capsys):
    d = copy_frames(tmp_path / "d", stems=("00000",))
    before = (d / "00000.json").read_bytes()
    preds = tmp_path / "p.zip"
    zipfile.ZipFile(preds, "w").close()
    cases = [
        (["detect", "--data", str(d), "--out", str(d / "00000.zip")], "inside the dataset"),
        (["detect", "--data", str(d), "--out", str(tmp_path / "preds.json")], "must end in .zip"),
        (["detect", "--data", str(d), "--out", str(d / "preds.zip")], "inside the dataset"),
        (["calibrate", "--data", str(d), "--out", str(d / "cams.zip")], "inside the dataset"),
        (["calibrate", "--data", str(d), "--out", str(tmp_path / "c.zip"), "--report", str(tmp_path / "c.zip")],
         "would overwrite the input"),
        (["calibrate", "--data", str(d), "--detections", str(preds), "--out", str(preds)], "would overwrite the input"),
        (["labels", "--data", str(d), "--out", str(d / "labels")], "inside the dataset"),
        (["sheet", "--data", str(d), "--out", str(d / "sheet.png")], "inside the dataset"),
        (["sheet", "--data", str(d), "--out", str(tmp_path / "sheet.txt")], ".png or .jpg"),
        (["eval", "--gt", str(d), "--pred", str(preds), "--csv", str(preds)], "would overwrite the input"),
    ]
    for argv, needle in cases:
        assert main(argv + ["--no-progress"] * (argv[0] in ("detect", "calibrate", "eval"))) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("error: --") and needle in err and err.count("\n") == 1, err
    assert (d / "00000.json").read_bytes() == before and sorted(os.listdir(d)) == ["00000.jpg", "00000.json"]


# ------------------------------------------------------------------------------ 5. nothing to do
@pytest.mark.parametrize("layout", ["empty", "two levels down"])
def test_no_frames_is_an_error_for_every_command(tmp_path, capsys, layout):
    d = tmp_path / "d"
    d.mkdir()
    if layout == "two levels down":
        copy_frames(d / "a" / "b", stems=("00000",))
    cams = tmp_path / "c.zip"
    zipfile.ZipFile(cams, "w").close()
    for argv in (["validate", "--data", str(d)],
                 ["calibrate", "--data", str(d), "--out", str(tmp_path / "o.zip"), "--no-progress"],
                 ["detect", "--data", str(d), "--out", str(tmp_path / "p.zip"), "--no-progress"],
                 ["labels", "--data", str(d), "--out", str(tmp_path / "labels")],
                 ["sheet", "--data", str(d), "--out", str(tmp_path / "s.png")],
                 ["eval", "--gt", str(d), "--pred", str(cams), "--no-progress"]):
        assert main(argv) == 1, argv
        assert one_line(capsys.readouterr().err, "no frames") == (
            f"error: {d}: no frames (expected <stem>.jpg/.png/.json at the top level, inside one folder, "
            f"or in split folders or zips)")


def test_eval_without_any_matching_camera_fails(tmp_path, capsys):
    gt = copy_frames(tmp_path / "gt", images=False)
    cams = tmp_path / "c.zip"
    write_camera_zip(cams, {"99": json.loads((SAMPLE / "cameras" / "camera_00000.json").read_text())})
    assert main(["eval", "--gt", str(gt), "--pred", str(cams), "--no-progress"]) == 1
    assert "no camera matches a frame" in one_line(capsys.readouterr().err, "error:")


def test_labels_without_annotations_fails(tmp_path, capsys):
    d = tmp_path / "d"
    d.mkdir()
    shutil.copy(SAMPLE / "00000.jpg", d / "00000.jpg")
    assert main(["labels", "--data", str(d), "--out", str(tmp_path / "labels")]) == 1
    assert "no annotated frame" in one_line(capsys.readouterr().err, "error:")


# --------------------------------------------------------------------------- 6. duplicate stems
def test_duplicate_stems_follow_a_fixed_rule_and_are_reported(tmp_path, capsys):
    d = copy_frames(tmp_path / "d", stems=("00000",))
    shutil.copy(SAMPLE / "00001.json", d / "00000.JSON")
    shutil.copy(SAMPLE / "00001.json", d / "00001.Json")
    shutil.copy(SAMPLE / "00001.json", d / "00001.JSON")
    png = cv2.imencode(".png", np.zeros((8, 8, 3), np.uint8))[1].tobytes()
    (d / "00000.png").write_bytes(png)
    (d / "00001.PNG").write_bytes(png)
    (d / "00001.png").write_bytes(png)
    ds = open_dataset(d)
    assert ds.frame("00000").annotation_path == str(d / "00000.json")
    assert ds.frame("00000").image_path == str(d / "00000.jpg")
    assert ds.frame("00001").annotation_path == str(d / "00001.JSON")  # no .json: the first name sorted
    assert ds.frame("00001").image_path == str(d / "00001.png")  # lower-case extension first
    rejected = sorted(str(e) for e in ds.rejected)
    assert len(rejected) == 4
    assert rejected[0].startswith(f"{d / '00000.JSON'}: another annotation of frame '00000' is used (00000.json)")
    assert main(["validate", "--data", str(d)]) == 1
    err = capsys.readouterr().err
    assert "4 problem(s)" in err and err.count("is used") == 4


def test_duplicate_stems_in_a_zip_do_not_depend_on_member_order(tmp_path):
    winners = set()
    for order in (["00001.JSON", "00001.json", "00001.png", "00001.jpg"], ["00001.jpg", "00001.png", "00001.json", "00001.JSON"]):
        z = tmp_path / f"{order[0]}.zip"
        with zipfile.ZipFile(z, "w") as zf:
            for name in order:
                zf.writestr(name, "{}")
        ds = open_dataset(z)
        winners.add((ds.frame("00001").annotation_path, ds.frame("00001").image_path))
        assert len(ds.rejected) == 2
    assert winners == {("00001.json", "00001.jpg")}
    z = tmp_path / "twice.zip"
    with pytest.warns(UserWarning), zipfile.ZipFile(z, "w") as zf:
        zf.writestr("1.json", "{}")
        zf.writestr("1.json", "{}")
    assert "appears twice" in str(open_dataset(z).rejected[0])


# ------------------------------------------------------------------ 7. validate reads cameras/
@pytest.mark.parametrize("as_zip", [False, True])
def test_validate_checks_every_camera(tmp_path, capsys, as_zip):
    d = copy_frames(tmp_path / "d", images=False, cameras=True)
    (d / "cameras" / "camera_00001.json").write_text('{"pan_degrees": 1}')
    shutil.copy(SAMPLE / "cameras" / "camera_00005.json", d / "cameras" / "camera_00005.json")
    data = d
    if as_zip:
        data = tmp_path / "d.zip"
        shutil.make_archive(str(data.with_suffix("")), "zip", d)
    assert main(["validate", "--data", str(data)]) == 1
    out, err = capsys.readouterr()
    assert "3 frames, 3 valid annotations, 0 images, 3 valid cameras" in out
    one_line(err, "camera_00001.json", "missing key")
    one_line(err, "camera_00005.json", "camera without a frame")
    assert "2 problem(s)" in err


# ---------------------------------------------------------------------- 8. size and pixel caps
def test_image_size_from_the_header(tmp_path):
    from pnlviz.data.imagesize import header_size
    img = np.zeros((37, 53, 3), np.uint8)
    for ext, params in ((".png", []), (".jpg", []), (".jpg", [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])):
        data = cv2.imencode(ext, img, params)[1].tobytes()
        assert header_size(iter_reader(data), "f") == (53, 37)
    jpeg = cv2.imencode(".jpg", img)[1].tobytes()
    app1 = b"\xff\xe1" + struct.pack(">H", 60002) + b"\xc0" * 60000  # a big EXIF-like segment
    dht = b"\xff\xc4" + struct.pack(">H", 7) + b"\x00\x10\x00\x00\x00"  # 0xC4 is no frame header
    assert decode_image(jpeg[:2] + app1 + jpeg[2:], "f").shape == (37, 53, 3)
    crafted = jpeg[:2] + app1 + b"\xff" + dht + jpeg[2:]  # with a fill byte
    assert header_size(iter_reader(crafted), "f") == (53, 37)
    for data, needle in ((jpeg[:2] + app1[:100], "ends before"), (b"GIF89a....", "neither a PNG nor a JPEG"),
                         (b"\xff\xd8\xff\xd9", "without a frame header"), (b"", "empty")):
        with pytest.raises(DataError, match=needle):
            header_size(iter_reader(data), "f.jpg")


def iter_reader(data: bytes):
    import io

    return io.BytesIO(data).read


def test_huge_image_is_refused_before_decoding(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    png_header_only(d / "00001.png", 30000, 30000)
    shutil.copy(d / "00001.png", d / "00002.jpg")  # PNG bytes under a .jpg name
    z = tmp_path / "d.zip"
    shutil.make_archive(str(z.with_suffix("")), "zip", d)
    for ds in (open_dataset(d), open_dataset(z)):
        for stem in ("00001", "00002"):
            for read in (ds.image_size, ds.image):
                with pytest.raises(DataError, match="image too large: 30000x30000 pixels .900 megapixels; the limit is 50"):
                    read(stem)


def test_member_and_file_sizes_are_capped_before_reading(tmp_path, capsys):
    z = zip_frames(tmp_path / "d.zip", images=True)
    patch_zip(z, "00001.json", size=2**31)  # the header says 2 GiB
    patch_zip(z, "00002.jpg", size=2**31)
    ds = open_dataset(z)
    with pytest.raises(DataError) as ei:
        ds.annotation("00001")
    assert str(ei.value) == f"{z}:00001.json: file too large: 2.0 GiB (the limit for this kind of file is 4 MiB)"
    for read in (ds.image, ds.image_size):
        with pytest.raises(DataError, match="00002.jpg: file too large: 2.0 GiB .* 256 MiB"):
            read("00002")
    assert main(["validate", "--data", str(z), "--images"]) == 1
    assert capsys.readouterr().err.count("file too large") == 2

    d = copy_frames(tmp_path / "d", stems=("00000",))
    os.truncate(d / "00000.json", 4 * 2**20 + 1)  # sparse: costs no disk; an annotation's cap is 4 MiB
    big = d / "00001.jpg"
    big.touch()
    os.truncate(big, 256 * 2**20 + 1)  # the image cap
    ds = open_dataset(d)
    with pytest.raises(DataError, match="00000.json: file too large: 4 MiB"):
        ds.annotation("00000")
    with pytest.raises(DataError, match="00001.jpg: file too large"):
        ds.image_size("00001")
    with pytest.raises(DataError, match="file too large"):
        read_camera_zip(patched_camera_zip(tmp_path))


def patched_camera_zip(tmp_path: Path) -> Path:
    z = tmp_path / "cams.zip"
    write_camera_zip(z, {"1": json.loads((SAMPLE / "cameras" / "camera_00000.json").read_text())})
    patch_zip(z, "camera_1.json", size=2**31)
    return z


# ------------------------------------------------------------------------------ detect (torch)
def test_detect_streams_and_keeps_frames_when_interrupted(tmp_path, monkeypatch, capsys):
    pytest.importorskip("torch")
    from pnlviz.data import read_predictions_info
    from pnlviz.detect.run import Detector

    d = copy_frames(tmp_path / "d", stems=("00000", "00001", "00002"))
    shutil.copy(SAMPLE / "00003.jpg", bad_name(d, BAD + b".jpg"))
    real, calls = Detector.detect, []

    def interrupt_third(self, images):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(self, images)

    monkeypatch.setattr(Detector, "detect", interrupt_third)
    out = tmp_path / "preds.zip"
    assert main(["detect", "--data", str(d), "--out", str(out), "--no-progress", "--threads", "1", "--settings",
                 str(tmp_path / "preds.json")]) == 130
    err = capsys.readouterr().err
    assert one_line(err, "interrupted") == f"interrupted: kept 2 of 3 frames in {out}"
    one_line(err, "not valid UTF-8")
    assert zipfile.ZipFile(out).namelist() == ["00000.json", "00001.json"]
    assert read_predictions_info(out)["frames"] == 2
    assert sorted(os.listdir(tmp_path)) == ["d", "preds.json", "preds.zip"]
