"""Loading and saving detector weights with readable errors.

``load_checkpoint`` accepts a path or an in-memory mapping that is either a
plain state dict or one of the common wrappers (``{"state_dict": ...}``,
``{"model": ...}``, ... and keys prefixed with ``module.`` by
``DataParallel``). Loading is strict: every model tensor must be present with
the same shape and the checkpoint must hold nothing else. Any problem raises
:class:`CheckpointError` with a one-paragraph message naming the offending
tensors, never a raw ``RuntimeError`` from ``torch``.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import torch
from torch import nn

__all__ = ["CheckpointError", "load_checkpoint", "save_checkpoint"]

#: Keys under which training scripts commonly nest the state dict.
WRAPPER_KEYS = ("state_dict", "model_state_dict", "model", "net", "network", "weights")
#: Prefixes added by ``nn.DataParallel`` / ``DistributedDataParallel`` and ``torch.compile``.
PREFIXES = ("module.", "_orig_mod.")
#: How many tensor names each part of an error message lists.
MAX_LISTED = 4

# Output channels of the published heads, to name a swapped checkpoint.
_HEAD_KINDS = {58: "keypoint", 24: "line"}


class CheckpointError(ValueError):
    """A checkpoint could not be read or does not fit the model."""


def _shape(shape: Any) -> str:
    return "[" + ", ".join(str(int(s)) for s in shape) + "]"


#: the largest checkpoint read (PnLCalib's HRNet checkpoints are about 250 MB)
MAX_CHECKPOINT_BYTES = 2 * 2**30


def _listed(items: list[str]) -> str:
    shown = ", ".join(items[:MAX_LISTED])
    if len(items) > MAX_LISTED:
        shown += f" and {len(items) - MAX_LISTED} more"
    return shown


def _read(source: str | os.PathLike[str], weights_only: bool) -> Any:
    path = Path(source)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist or is not a file.")
    if path.stat().st_size > MAX_CHECKPOINT_BYTES:
        raise CheckpointError(f"checkpoint {path} is {path.stat().st_size / 2**30:.1f} GiB: larger than any network "
                              f"here ({MAX_CHECKPOINT_BYTES / 2**30:.0f} GiB at most); not read.")
    try:
        return torch.load(path, map_location="cpu", weights_only=weights_only)
    except Exception as exc:  # torch raises many types for corrupt / foreign files
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        hint = (
            " It may pickle objects other than tensors; only load it with weights_only=False if you trust its source."
            if weights_only and "weights_only" in str(exc)
            else ""
        )
        raise CheckpointError(f"checkpoint {path} could not be read by torch.load: {first_line}.{hint}") from None


def _unwrap(obj: Any, label: str) -> dict[str, torch.Tensor]:
    """Find the state dict inside common wrappers and strip wrapper prefixes."""
    for _ in range(3):  # e.g. {"model": {"state_dict": ...}}
        if not isinstance(obj, Mapping):
            break
        if obj and all(isinstance(v, torch.Tensor) for v in obj.values()):
            break
        inner = next((obj[k] for k in WRAPPER_KEYS if isinstance(obj.get(k), Mapping)), None)
        if inner is None:
            break
        obj = inner
    if not isinstance(obj, Mapping):
        raise CheckpointError(
            f"{label} holds a {type(obj).__name__}, not a state dict (a mapping of tensor names to tensors)."
        )
    if not obj:
        raise CheckpointError(f"{label} is an empty state dict.")
    not_tensors = [str(k) for k, v in obj.items() if not isinstance(v, torch.Tensor)]
    if not_tensors:
        raise CheckpointError(
            f"{label} is not a state dict: entries {_listed(not_tensors)} are not tensors "
            f"(recognised wrapper keys: {', '.join(WRAPPER_KEYS)})."
        )
    state = {str(k): v for k, v in obj.items()}
    for prefix in PREFIXES:
        if all(k.startswith(prefix) for k in state):
            state = {k[len(prefix) :]: v for k, v in state.items()}
    return state


def _mismatch_message(model: nn.Module, state: Mapping[str, torch.Tensor], label: str) -> str | None:
    expected = model.state_dict()
    missing = [k for k in expected if k not in state]
    unexpected = [k for k in state if k not in expected]
    misshaped = [k for k in expected if k in state and tuple(state[k].shape) != tuple(expected[k].shape)]
    if not (missing or unexpected or misshaped):
        return None
    parts = []
    if misshaped:
        shown = [
            f"{k}: checkpoint {_shape(state[k].shape)} vs model {_shape(expected[k].shape)}"
            for k in misshaped[:MAX_LISTED]
        ]
        more = f" and {len(misshaped) - MAX_LISTED} more" if len(misshaped) > MAX_LISTED else ""
        parts.append(f"{len(misshaped)} tensor(s) have the wrong shape ({'; '.join(shown)}{more})")
    if missing:
        parts.append(f"{len(missing)} model tensor(s) are missing from the checkpoint ({_listed(missing)})")
    if unexpected:
        parts.append(f"{len(unexpected)} checkpoint tensor(s) are not in the model ({_listed(unexpected)})")
    message = f"{label} does not fit {type(model).__name__}: " + "; ".join(parts) + "."

    # Name the likely cause when only the output layer differs (keypoint vs line network).
    head = [k for k in misshaped if k.startswith("head.")]
    if head and head == misshaped and not missing and not unexpected:
        got = _HEAD_KINDS.get(int(state[head[0]].shape[0]))
        want = _HEAD_KINDS.get(int(expected[head[0]].shape[0]))
        if got and want and got != want:
            message += f" Is this a {got}-network checkpoint given where the {want} network's weights are expected?"
    elif missing and not unexpected and not misshaped:
        message += " The checkpoint looks truncated or belongs to a smaller architecture."
    return message


ModuleT = TypeVar("ModuleT", bound=nn.Module)


def load_checkpoint(
    model: ModuleT,
    path_or_state_dict: str | os.PathLike[str] | Mapping[str, Any],
    *,
    weights_only: bool = True,
) -> ModuleT:
    """Load weights into ``model`` strictly and return it.

    ``path_or_state_dict`` is a file written by ``torch.save`` or an in-memory
    mapping; plain state dicts, wrappers such as ``{"state_dict": sd}`` /
    ``{"model": sd}`` and ``module.``-prefixed keys are accepted. Files are read
    on the CPU with ``torch.load(weights_only=True)`` unless told otherwise.

    Raises :class:`CheckpointError` when the file cannot be read or the
    tensors do not match the model's names and shapes exactly.
    """
    if isinstance(path_or_state_dict, Mapping):
        label = "the given state dict"
        obj: Any = path_or_state_dict
    else:
        label = f"checkpoint {Path(path_or_state_dict)}"
        obj = _read(path_or_state_dict, weights_only)
    state = _unwrap(obj, label)
    message = _mismatch_message(model, state, label)
    if message:
        raise CheckpointError(message)
    try:
        model.load_state_dict(state, strict=True)
    except Exception as exc:  # names and shapes fit, so this is e.g. a dtype problem
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CheckpointError(f"{label} could not be loaded into {type(model).__name__}: {first_line}") from None
    return model


def save_checkpoint(model: nn.Module, path: str | os.PathLike[str]) -> Path:
    """Write ``model.state_dict()`` (a plain state dict) to ``path`` atomically."""
    from pnlviz.data.atomic import refuse_non_regular

    path = Path(path)
    refuse_non_regular(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        try:
            torch.save(model.state_dict(), tmp)
        except RuntimeError as exc:  # torch reports a failed write (a full disk) as a RuntimeError
            free = shutil.disk_usage(path.parent).free
            reason = "No space left on device" if free < 2**20 else str(exc).strip().splitlines()[0][:120]
            raise OSError(errno.ENOSPC if free < 2**20 else errno.EIO, reason, str(path)) from None
        refuse_non_regular(path)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
