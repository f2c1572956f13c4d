"""A light keypoint + line detector with the published networks' output contract (issue #5).

``LightNet`` is a compact encoder-decoder with ONE shared trunk and two heads:

    input   RGB, 3 x H x W, values in [0, 1]
    stem    3x3 s2 conv 3 -> 16, 3x3 conv 16 -> 16                        -> e2  16 @ H/2
    enc4    3x3 s2 conv 16 -> 24, 1 residual block                        -> e4  24 @ H/4
    enc8    3x3 s2 conv 24 -> 48, 2 residual blocks                       -> e8  48 @ H/8
    enc16   3x3 s2 conv 48 -> 80, 2 residual blocks                       -> e16 80 @ H/16
    enc32   3x3 s2 conv 80 -> 128, 2 residual blocks (the second dilated x2)
            + global context (image-wide mean -> 1x1 conv -> ReLU, added) -> e32 128 @ H/32
    decoder U-Net steps: bilinear up to the skip's exact size, concat, 3x3 conv (+ residual block)
            128+80 -> 80 @ H/16 (+1 block), 80+48 -> 48 @ H/8 (+1 block),
            48+24 -> 32 @ H/4, 32+16 -> 24 @ H/2
    heads   per head: 3x3 conv 24 -> 24, BN, ReLU, 1x1 conv -> C
            keypoints C = 58, softmax over channels (57 keypoints + background)
            lines     C = 24, element-wise sigmoid (23 line extremities + all line bodies)
    output  C x ceil(H/2) x ceil(W/2) (``H/2 x W/2`` for even sides, like the published networks)

1.48 M parameters (5.7 MiB as a float32 state dict); ~7.4 GMAC and ~130 ms per 960x540 frame
on 2 CPU threads (``benchmarks/bench_detect.py``), ~60 ms at the 480x272 training size.

Residual blocks are ResNet basic blocks (two 3x3 conv + BN, identity shortcut). Sizes are
handled with explicit interpolation targets, so any input size works (e.g. 960x540, odd sizes).

:class:`pnlviz.detect.run.Detector` takes one network per head; ``LightNet.kp_head_module()`` and
``LightNet.line_head_module()`` are thin views on the same network. In inference mode the trunk
runs once per input: the view called first computes both heads and the other view picks up the
cached result when it is called with the same tensor (as ``Detector.heatmaps`` does).

``pnlviz.detect.run.light_detector(path)`` builds a ``Detector`` from a checkpoint written by
:mod:`pnlviz.detect.train` (its JSON sidecar gives the input size the model was trained at).
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from pnlviz.detect.default import read_sidecar, sidecar_path  # noqa: F401 (torch-free; re-exported)
from pnlviz.detect.hrnet import KEYPOINT_CHANNELS, LINE_CHANNELS

__all__ = ["LightNet", "HeadView", "load_light", "read_sidecar", "sidecar_path"]

ENCODER_WIDTHS = (16, 24, 48, 80, 128)
ENCODER_BLOCKS = (0, 1, 2, 2, 2)
DECODER_WIDTHS = (80, 48, 32, 24)
DECODER_BLOCKS = (1, 1, 0, 0)
HEAD_WIDTH = 24


def _cbr(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride=stride, padding=dilation, dilation=dilation, bias=False),
                         nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class ResBlock(nn.Module):
    """ResNet basic block: two 3x3 conv + BN with an identity shortcut."""

    def __init__(self, channels: int, dilation: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=dilation, dilation=dilation, bias=False)
        self.bn1 = nn.BatchNorm2d(channels)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)), inplace=True)
        return F.relu(self.bn2(self.conv2(out)) + x, inplace=True)


class _Up(nn.Module):
    """Decoder step: upsample to the skip's size, concatenate, 3x3 conv, residual block."""

    def __init__(self, cin: int, cskip: int, cout: int, blocks: int = 1) -> None:
        super().__init__()
        self.fuse = _cbr(cin + cskip, cout)
        self.block = nn.Sequential(*(ResBlock(cout) for _ in range(blocks)))

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return self.block(self.fuse(torch.cat([x, skip], dim=1)))


def _head(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(_cbr(cin, HEAD_WIDTH), nn.Conv2d(HEAD_WIDTH, cout, 1))


def _last_bias(head: nn.Sequential) -> torch.Tensor:
    """The bias of a :func:`_head`'s output convolution."""
    last = head[-1]
    assert isinstance(last, nn.Conv2d) and last.bias is not None
    return last.bias


class LightNet(nn.Module):
    """Shared-trunk keypoint (58, softmax) + line (24, sigmoid) network at half resolution."""

    def __init__(self) -> None:
        super().__init__()
        w = ENCODER_WIDTHS
        self.stem = nn.Sequential(_cbr(3, w[0], 2), _cbr(w[0], w[0]))
        stages = []
        for i in range(1, len(w)):
            layers: list[nn.Module] = [_cbr(w[i - 1], w[i], 2)]
            for b in range(ENCODER_BLOCKS[i]):
                last = i == len(w) - 1 and b == ENCODER_BLOCKS[i] - 1
                layers.append(ResBlock(w[i], dilation=2 if last else 1))
            stages.append(nn.Sequential(*layers))
        self.encoder = nn.ModuleList(stages)
        self.context = nn.Sequential(nn.Conv2d(w[-1], w[-1], 1), nn.ReLU(inplace=True))
        d = DECODER_WIDTHS
        skips = list(reversed(w[:-1]))  # 96, 64, 32, 24
        ins = [w[-1]] + list(d[:-1])
        self.decoder = nn.ModuleList(_Up(ins[i], skips[i], d[i], DECODER_BLOCKS[i]) for i in range(len(d)))
        self.kp_head = _head(d[-1], KEYPOINT_CHANNELS)
        self.line_head = _head(d[-1], LINE_CHANNELS)
        # Start from "nothing here" (each keypoint and line channel at p ~ 0.01), as focal-loss
        # detectors do: the loss then spends its first steps finding peaks, not emptying the maps.
        kp_bias, line_bias = _last_bias(self.kp_head), _last_bias(self.line_head)
        with torch.no_grad():
            kp_bias.zero_()
            kp_bias[-1] = math.log(100.0 - (KEYPOINT_CHANNELS - 1))  # softmax: 1 / (43 + 57)
            line_bias.fill_(-math.log(99.0))
        self._cache: tuple | None = None

    # -- forward -----------------------------------------------------------------------------
    def features(self, x: torch.Tensor) -> torch.Tensor:
        """The shared 32-channel decoder output at half the input resolution."""
        feats = [self.stem(x)]
        for stage in self.encoder:
            feats.append(stage(feats[-1]))
        y = feats[-1]
        y = y + self.context(y.mean(dim=(2, 3), keepdim=True))
        for up, skip in zip(self.decoder, reversed(feats[:-1])):
            y = up(y, skip)
        return y

    def logits(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(keypoint logits (B, 58, h, w), line logits (B, 24, h, w)) before the activations."""
        f = self.features(x)
        return self.kp_head(f), self.line_head(f)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(keypoint heatmaps, softmax over channels; line heatmaps, sigmoid)."""
        kp, lines = self.logits(x)
        return torch.softmax(kp, dim=1), torch.sigmoid(lines)

    # -- Detector adapters ---------------------------------------------------------------------
    def head_output(self, x: torch.Tensor, head: str) -> torch.Tensor:
        """One head's heatmaps; without grad, both heads are computed once per input tensor."""
        if torch.is_grad_enabled() and self.training:
            return self.forward(x)[0 if head == "kp" else 1]
        # The cache holds the input itself (so its id cannot be reused while cached) and its
        # version counter (in-place changes invalidate it; inference tensors have none).
        version = -1 if x.is_inference() else x._version
        cache = self._cache
        if cache is None or cache[0] is not x or cache[1] != version:
            kp, lines = self.forward(x)
            cache = self._cache = (x, version, {"kp": kp, "lines": lines})
        out = cache[2].pop(head, None)
        if out is None:  # the same head asked twice for the same tensor: recompute
            self._cache = None
            return self.forward(x)[0 if head == "kp" else 1]
        if not cache[2]:
            self._cache = None
        return out

    def kp_head_module(self) -> "HeadView":
        return HeadView(self, "kp")

    def line_head_module(self) -> "HeadView":
        return HeadView(self, "lines")


class HeadView(nn.Module):
    """One head of a :class:`LightNet` as a network of its own (``forward(x) -> heatmaps``)."""

    def __init__(self, net: LightNet, head: str) -> None:
        super().__init__()
        if head not in ("kp", "lines"):
            raise ValueError(f"head must be 'kp' or 'lines', not {head!r}")
        self.net = net
        self.head = head

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net.head_output(x, self.head)


# -- files ---------------------------------------------------------------------------------------
def load_light(weights: str | Path) -> LightNet:
    """A :class:`LightNet` with the weights of ``weights`` (strict), in eval mode."""
    from pnlviz.detect.checkpoint import load_checkpoint

    return load_checkpoint(LightNet(), weights).eval()
