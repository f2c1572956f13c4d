"""Batches on a dask cluster (issue #15): the same bytes as a local run, a lost worker costs
nothing but time."""

import json
import os
import signal
import threading
import time
import zipfile

import pytest

distributed = pytest.importorskip("distributed")

from helpers import copy_sample_frames, sn22_first  # noqa: E402

from pnlviz.cli import main  # noqa: E402
from pnlviz.data.zipwriter import journal_path  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as c, distributed.Client(c) as client:
        yield c, client


def test_calibrate_on_the_cluster_writes_the_local_bytes(tmp_path, shared_dir, cluster):
    gt = sn22_first(shared_dir, tmp_path / "sn22.zip", 160)
    local, remote = tmp_path / "local.zip", tmp_path / "remote.zip"
    assert main(["calibrate", "--data", str(gt), "--out", str(local), "--no-progress"]) == 0
    assert main(["calibrate", "--data", str(gt), "--out", str(remote), "--no-progress",
                 "--scheduler", cluster[0].scheduler_address, "--chunk", "40"]) == 0
    assert remote.read_bytes() == local.read_bytes()


def test_detect_on_the_cluster_writes_the_local_bytes(tmp_path, cluster):
    pytest.importorskip("torch")
    frames = copy_sample_frames(tmp_path / "frames", 6)
    local, remote = tmp_path / "local.zip", tmp_path / "remote.zip"
    assert main(["detect", "--data", str(frames), "--out", str(local), "--no-progress", "--threads", "1"]) == 0
    assert main(["detect", "--data", str(frames), "--out", str(remote), "--no-progress",
                 "--scheduler", cluster[0].scheduler_address, "--chunk", "2"]) == 0
    assert remote.read_bytes() == local.read_bytes()


def test_a_worker_killed_mid_run_loses_no_frame(tmp_path, shared_dir):
    """One of two workers is killed (SIGKILL) once the first results are in: its tasks are redone
    elsewhere and the output is the local run's, frame for frame."""
    gt = sn22_first(shared_dir, tmp_path / "sn22.zip", 160)
    local, remote = tmp_path / "local.zip", tmp_path / "remote.zip"
    assert main(["calibrate", "--data", str(gt), "--out", str(local), "--no-progress"]) == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=50) as c, distributed.Client(c) as client:
        pids = list(client.run(os.getpid).values())
        codes = []
        run = threading.Thread(target=lambda: codes.append(main(
            ["calibrate", "--data", str(gt), "--out", str(remote), "--no-progress", "--scheduler", c.scheduler_address,
             "--chunk", "10"])))
        run.start()
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            j = journal_path(remote)
            if j.is_file() and j.read_text().count("\n") >= 10:
                break
            time.sleep(0.05)
        os.kill(pids[0], signal.SIGKILL)
        run.join(timeout=300)
        assert codes == [0]
        assert pids[0] not in client.run(os.getpid).values()  # that worker is gone (its nanny started another)
    with zipfile.ZipFile(local) as a, zipfile.ZipFile(remote) as b:
        assert a.namelist() == b.namelist() and all(a.read(n) == b.read(n) for n in a.namelist())


def test_cluster_options_fail_clearly(tmp_path, shared_dir, capsys):
    gt = shared_dir / "data" / "sn22_test_subset" / "annotations.zip"
    with pytest.raises(SystemExit, match="cannot connect"):
        main(["calibrate", "--data", str(gt), "--out", str(tmp_path / "c.zip"), "--scheduler", "tcp://127.0.0.1:1"])
    capsys.readouterr()
    with pytest.raises(SystemExit) as refused:  # refused as the options are read, before any cluster starts
        main(["calibrate", "--data", str(gt), "--out", str(tmp_path / "c.zip"), "--dask", "1", "--chunk", "0"])
    assert refused.value.code == 2
    assert "argument --chunk: expected a whole number >= 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "c.zip").exists()


def test_labels_on_the_cluster_write_the_local_files_and_resume(tmp_path, shared_dir, cluster, capsys):
    gt = shared_dir / "data" / "wc14_test_half" / "annotations.zip"
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert main(["labels", "--data", str(gt), "--out", str(local)]) == 0
    assert main(["labels", "--data", str(gt), "--out", str(remote), "--scheduler", cluster[0].scheduler_address,
                 "--chunk", "10"]) == 0
    names = sorted(p.name for p in local.glob("*.json"))
    assert len(names) == 93 and names == sorted(p.name for p in remote.glob("*.json"))
    assert all((local / n).read_bytes() == (remote / n).read_bytes() for n in names)
    for n in names[:50]:  # as if the run had stopped after 43 frames
        (remote / n).unlink()
    capsys.readouterr()
    assert main(["labels", "--data", str(gt), "--out", str(remote), "--resume"]) == 0
    assert "resuming: 43 frames already labelled" in capsys.readouterr().out
    assert all((local / n).read_bytes() == (remote / n).read_bytes() for n in names)


def test_export_on_the_cluster_writes_the_local_files(tmp_path, shared_dir, cluster):
    """`pnlviz export` on the cluster: the workers open the data and the edits read-only where they
    are; every label file is the local run's, byte for byte. A second run on the same cluster sees
    an edit made in between (the workers do not keep the edits they read before)."""
    from pnlviz.app.state import AppState
    from pnlviz.pipeline.export import read_export_zip

    data = tmp_path / "set"
    data.mkdir()
    with zipfile.ZipFile(shared_dir / "data" / "sn22_test_subset" / "annotations.zip") as z:
        for name in sorted(n for n in z.namelist() if n.endswith(".json"))[:24]:
            (data / os.path.basename(name)).write_bytes(z.read(name))
    edits = tmp_path / "edits"
    with AppState(data, edits=edits) as st:
        stems = st.stems
        for stem in stems[:20]:
            st.set_review(stem, "accepted")
        kid = int(st.view(stems[3]).observations.kp_ids[0])
        st.move_keypoint(stems[3], kid, 321.0, 123.0)
    common = ["export", "--data", str(data), "--edits", str(edits), "--no-progress"]
    local, remote = tmp_path / "local.zip", tmp_path / "remote.zip"
    assert main(common + ["--out", str(local)]) == 0
    assert main(common + ["--out", str(remote), "--scheduler", cluster[0].scheduler_address, "--chunk", "3"]) == 0
    members, manifest = read_export_zip(local)
    assert len(manifest["frames"]) == 20 and manifest["frames"][stems[3]]["keypoints_edited"] == [kid]
    assert sum(n.startswith("cameras/") for n in members) >= 18
    assert read_export_zip(remote) == (members, manifest)
    # a folder output holds the same files
    folder = tmp_path / "folder"
    assert main(common + ["--out", str(folder), "--dask", "1"]) == 0
    assert {n: (folder / n).read_bytes() for n in members} == members
    # an edit between two runs on the same cluster is in the second
    with AppState(data, edits=edits) as st:
        st.set_review(stems[22], "corrected")
        st.move_keypoint(stems[3], kid, 300.0, 100.0)
    again = tmp_path / "again.zip"
    assert main(common + ["--out", str(again), "--scheduler", cluster[0].scheduler_address, "--chunk", "3"]) == 0
    members2, manifest2 = read_export_zip(again)
    assert stems[22] in manifest2["frames"] and len(manifest2["frames"]) == 21
    kps = json.loads(members2[f"keypoints/{stems[3]}.json"])["keypoints"][str(kid)]
    assert (kps["x"], kps["y"]) == (300.0, 100.0)
