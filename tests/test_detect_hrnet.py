"""PnLCalib-compatible HRNet detectors: checkpoint layout, forward wiring, checkpoint I/O.

The reference facts live in ``../shared/reference`` (tensor names/shapes of the
published checkpoints and a forward fixture computed with deterministic
weights); the tests that need them skip without it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

from pnlviz.detect.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from pnlviz.detect.hrnet import PnLCalibNet, keypoint_net, line_net
from helpers import needs_shared  # noqa: E402

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference"
SHAPES = REFERENCE / "pnlcalib_state_dict_shapes.json"
FIXTURE = REFERENCE / "pnlcalib_forward_fixture.npz"


FACTORIES = {"kp": keypoint_net, "lines": line_net}


def fill_deterministic(model: torch.nn.Module) -> torch.nn.Module:
    """Fill every tensor as the fixture's README describes, then switch to eval mode."""
    state = {}
    for name, tensor in model.state_dict().items():
        if not tensor.dtype.is_floating_point:  # num_batches_tracked
            state[name] = torch.zeros_like(tensor)
            continue
        k = (zlib.crc32(name.encode()) % 1000) / 100.0
        v = 0.02 * torch.sin(0.37 * torch.arange(tensor.numel(), dtype=torch.float64) + k)
        if name.endswith("running_var"):
            v = v.abs() + 1.0
        elif tensor.dim() == 1 and name.endswith(".weight"):  # norm scales
            v = 1.0 + v
        state[name] = v.reshape(tensor.shape).to(tensor.dtype)
    model.load_state_dict(state, strict=True)
    return model.eval()


@pytest.fixture(scope="module")
def reference_shapes() -> dict[str, dict[str, list[int]]]:
    return json.loads(SHAPES.read_text())


@pytest.fixture(scope="module")
def fixture_arrays() -> dict[str, np.ndarray]:
    with np.load(FIXTURE) as data:
        return {k: data[k] for k in data.files}


@pytest.fixture(scope="module")
def filled() -> dict[str, PnLCalibNet]:
    torch.manual_seed(0)
    return {key: fill_deterministic(factory()) for key, factory in FACTORIES.items()}


@pytest.fixture(scope="module")
def outputs(filled, fixture_arrays) -> dict[str, torch.Tensor]:
    x = torch.from_numpy(fixture_arrays["input"])
    with torch.inference_mode():
        return {key: net(x) for key, net in filled.items()}


def test_package_import_does_not_import_torch():
    code = "import sys, pnlviz.detect; assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_rejects_unknown_activation():
    with pytest.raises(ValueError, match="final_activation"):
        PnLCalibNet(3, "relu")  # type: ignore[arg-type]


@needs_shared
@pytest.mark.parametrize("key", ["kp", "lines"])
def test_state_dict_matches_published_checkpoints(key, reference_shapes):
    expected = reference_shapes[key]
    got = {name: list(t.shape) for name, t in FACTORIES[key]().state_dict().items()}
    assert len(got) == len(expected) == 1839
    assert sorted(set(got) ^ set(expected)) == []
    assert {n: s for n, s in got.items() if expected[n] != s} == {}
    assert list(got) == list(expected)  # same order too


@needs_shared
@pytest.mark.parametrize("key", ["kp", "lines"])
def test_forward_reproduces_fixture(key, outputs, fixture_arrays):
    got = outputs[key].double().numpy()
    want = fixture_arrays[key].astype(np.float64)
    assert got.shape == want.shape
    err = float(np.abs(got - want).max())
    print(f"{key}: max abs error vs fixture {err:.3g}")
    # The outputs vary little with these weights (kp 0.016-0.019, lines 0.48-0.52):
    # a wiring variant with nearest instead of bilinear fusion is off by 7e-6 / 9e-5,
    # so the tolerance must be much tighter than 1e-4 to pin the wiring.
    assert err < 2e-6, f"{key}: max abs error {err:.3g}"
    # Compare logits too (softmax up to a per-pixel constant, logit of the sigmoid).
    if key == "kp":
        lg, lw = np.log(got), np.log(want)
        lg, lw = lg - lg.mean(1, keepdims=True), lw - lw.mean(1, keepdims=True)
        np.testing.assert_allclose(got.sum(1), 1.0, atol=1e-5)
    else:
        lg, lw = np.log(got / (1 - got)), np.log(want / (1 - want))
    logit_err = float(np.abs(lg - lw).max())
    print(f"{key}: max abs logit error {logit_err:.3g}")
    assert logit_err < 1e-5


def test_arbitrary_input_size_gives_half_resolution():
    net = line_net().eval()
    with torch.inference_mode():
        y = net(torch.rand(1, 3, 72, 120))  # not multiples of 32
    assert y.shape == (1, 24, 36, 60)
    assert float(y.min()) >= 0.0 and float(y.max()) <= 1.0


@needs_shared
def test_line_checkpoint_into_keypoint_net_is_named(filled):
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(keypoint_net(), filled["lines"].state_dict())
    message = str(info.value)
    assert "head.0.3.weight: checkpoint [24, 784, 1, 1] vs model [58, 784, 1, 1]" in message
    assert "head.0.3.bias" in message
    assert "line-network checkpoint" in message and "keypoint" in message
    assert "\n" not in message


@needs_shared
def test_truncated_checkpoint_names_missing_tensors(filled, tmp_path):
    state = filled["kp"].state_dict()
    names = list(state)
    truncated = {k: state[k] for k in names[:-3]}
    path = tmp_path / "truncated.pth"
    torch.save(truncated, path)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(keypoint_net(), path)
    message = str(info.value)
    assert "3 model tensor(s) are missing" in message
    for name in names[-3:]:
        assert name in message
    assert "truncated" in message


def test_unexpected_and_misshaped_tensors_are_named():
    model = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1), torch.nn.BatchNorm2d(4))
    state = dict(model.state_dict())
    state["0.weight"] = torch.zeros(5, 3, 1, 1)
    state["extra.weight"] = torch.zeros(2)
    with pytest.raises(CheckpointError, match=r"0\.weight: checkpoint \[5, 3, 1, 1\] vs model \[4, 3, 1, 1\]") as info:
        load_checkpoint(model, state)
    assert "extra.weight" in str(info.value)


@pytest.mark.parametrize(
    "wrap",
    [
        lambda sd: sd,
        lambda sd: {"state_dict": sd, "epoch": 3},
        lambda sd: {"model": sd, "optimizer": {"lr": 0.1}},
        lambda sd: {f"module.{k}": v for k, v in sd.items()},
        lambda sd: {"state_dict": {f"module.{k}": v for k, v in sd.items()}},
    ],
    ids=["plain", "state_dict", "model", "module-prefix", "wrapped-prefixed"],
)
def test_common_wrappers_load(wrap, tmp_path):
    torch.manual_seed(1)
    source = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    target = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    obj = wrap(source.state_dict())
    load_checkpoint(target, obj)
    for k, v in source.state_dict().items():
        assert torch.equal(target.state_dict()[k], v)
    path = tmp_path / "wrapped.pt"
    torch.save(obj, path)
    target2 = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    load_checkpoint(target2, path)
    assert torch.equal(target2[0].weight, source[0].weight)


def test_unreadable_checkpoints_raise_checkpoint_error(tmp_path):
    model = torch.nn.Linear(2, 2)
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(model, tmp_path / "nope.pth")
    garbage = tmp_path / "garbage.pth"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="could not be read"):
        load_checkpoint(model, garbage)
    with pytest.raises(CheckpointError, match="not tensors"):
        load_checkpoint(model, {"weight": [1, 2], "bias": torch.zeros(2)})
    assert issubclass(CheckpointError, ValueError)


@needs_shared
def test_save_load_round_trip_is_identical(filled, outputs, fixture_arrays, tmp_path):
    path = save_checkpoint(filled["kp"], tmp_path / "sub" / "kp.pth")
    assert path.is_file()
    loaded = load_checkpoint(keypoint_net(), path).eval()
    with torch.inference_mode():
        y = loaded(torch.from_numpy(fixture_arrays["input"]))
    assert torch.equal(y, outputs["kp"])
    assert list(tmp_path.joinpath("sub").iterdir()) == [path]  # no temporary files left
