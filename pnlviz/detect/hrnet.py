"""PnLCalib-compatible keypoint and line-extremity networks (HRNetV2-W48).

Architecture (module names chosen so that the published checkpoints load with
``strict=True``; every shape below is fixed by those checkpoints)::

    input  RGB, 3 x H x W, values in [0, 1]
    conv1  3x3 stride 2, 3 -> 64                    -> skip features (before bn1), 64 @ H/2
           bn1, ReLU
    conv2  3x3 stride 2, 64 -> 64, bn2, ReLU        -> 64 @ H/4
    layer1 4 Bottlenecks (expansion 4)              -> 256 @ H/4
    transition1 -> branches 48 @ H/4, 96 @ H/8
    stage2  1 module,  2 branches, 4 BasicBlocks per branch
    transition2 -> adds 192 @ H/16 (from the lowest-resolution branch)
    stage3  4 modules, 3 branches
    transition3 -> adds 384 @ H/32
    stage4  3 modules, 4 branches (all modules keep multi-scale outputs)
    HRNetV2 representation: branches 2..4 upsampled (bilinear) to H/4 and
        concatenated with branch 1: 48 + 96 + 192 + 384 = 720 @ H/4
    x2 nearest upsampling to H/2, then concatenated (after it) with the raw conv1
        output (skip connection from the convolution stem at that resolution,
        taken before bn1/ReLU): 720 + 64 = 784 @ H/2
    head   1x1 conv 784 -> 784 (bias), BN, ReLU, 1x1 conv 784 -> C (bias)
    output C x H/2 x W/2, softmax over channels (keypoints, C = 58: 57 keypoint
        heatmaps + background) or sigmoid (lines, C = 24: the extremities of
        lines 1-23 + one channel of all line bodies)

Each high-resolution module runs its branches (residual blocks) and then fuses
them: output ``i`` is ``ReLU(sum_j f_ij(x_j))`` with ``f_ii`` the identity,
``f_ij`` for a lower-resolution ``j > i`` a 1x1 conv + BN followed by bilinear
upsampling (``align_corners=False``) to the size of branch ``i``, and for a
higher-resolution ``j < i`` a chain of ``i-j`` strided 3x3 conv + BN (+ ReLU
except after the last one).

The forward wiring (which stem tensor is the skip, interpolation modes, the
concatenation order, the ReLU in the head) is not fixed by the checkpoint's
tensor names; it was chosen among the plausible variants by reproducing a
reference forward fixture of the published architecture (deterministic
weights, see ``tests/test_detect_hrnet.py``): this variant reproduces the
head logits to ~2e-7, the next best variant is 50x further off.

Interpolation is done to explicit target sizes, so inputs whose sides are not
multiples of 32 (e.g. 960x540) work.
"""

from __future__ import annotations

from typing import Literal, cast

import torch
import torch.nn.functional as F
from torch import nn

__all__ = [
    "KEYPOINT_CHANNELS",
    "LINE_CHANNELS",
    "PnLCalibNet",
    "keypoint_net",
    "line_net",
]

KEYPOINT_CHANNELS = 58
LINE_CHANNELS = 24

BN_MOMENTUM = 0.1

#: Channel widths of the four resolution branches (HRNet-W48).
WIDTHS = (48, 96, 192, 384)
STEM_CHANNELS = 64
#: Number of high-resolution modules in stages 2, 3, 4.
MODULES_PER_STAGE = (1, 4, 3)
BLOCKS_PER_BRANCH = 4


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, momentum=BN_MOMENTUM)


def _conv3x3(cin: int, cout: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, kernel_size=3, stride=stride, padding=1, bias=False)


class BasicBlock(nn.Module):
    """Two 3x3 conv + BN with an identity shortcut (used in stages 2-4)."""

    expansion = 1

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv1 = _conv3x3(channels, channels)
        self.bn1 = _bn(channels)
        self.conv2 = _conv3x3(channels, channels)
        self.bn2 = _bn(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return F.relu(out + x)


class Bottleneck(nn.Module):
    """1x1 -> 3x3 -> 1x1 (x4 expansion) residual block of ``layer1``."""

    expansion = 4

    def __init__(self, cin: int, planes: int) -> None:
        super().__init__()
        cout = planes * self.expansion
        self.conv1 = nn.Conv2d(cin, planes, kernel_size=1, bias=False)
        self.bn1 = _bn(planes)
        self.conv2 = _conv3x3(planes, planes)
        self.bn2 = _bn(planes)
        self.conv3 = nn.Conv2d(planes, cout, kernel_size=1, bias=False)
        self.bn3 = _bn(cout)
        self.downsample: nn.Module | None = None
        if cin != cout:
            self.downsample = nn.Sequential(nn.Conv2d(cin, cout, kernel_size=1, bias=False), _bn(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = F.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        shortcut = x if self.downsample is None else self.downsample(x)
        return F.relu(out + shortcut)


def _conv_bn_relu(cin: int, cout: int, stride: int, relu: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = [_conv3x3(cin, cout, stride), _bn(cout)]
    if relu:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class HighResolutionModule(nn.Module):
    """Parallel residual branches followed by all-to-all multi-resolution fusion."""

    def __init__(self, widths: tuple[int, ...], num_blocks: int) -> None:
        super().__init__()
        self.widths = widths
        self.branches = nn.ModuleList(
            nn.Sequential(*(BasicBlock(w) for _ in range(num_blocks))) for w in widths
        )
        self.fuse_layers = nn.ModuleList()
        for i, wi in enumerate(widths):
            row = nn.ModuleList()
            for j, wj in enumerate(widths):
                if j > i:  # lower resolution -> 1x1 conv + BN, upsampled bilinearly in forward
                    row.append(nn.Sequential(nn.Conv2d(wj, wi, kernel_size=1, bias=False), _bn(wi)))
                elif j == i:
                    # torch types the items as modules; None (nothing to fuse) keeps the checkpoint's indices
                    row.append(None)  # type: ignore[arg-type]
                else:  # higher resolution -> (i - j) strided 3x3 convs
                    steps = [_conv_bn_relu(wj, wj, 2) for _ in range(i - j - 1)]
                    steps.append(_conv_bn_relu(wj, wi, 2, relu=False))
                    row.append(nn.Sequential(*steps))
            self.fuse_layers.append(row)

    def forward(self, xs: list[torch.Tensor]) -> list[torch.Tensor]:
        xs = [branch(x) for branch, x in zip(self.branches, xs)]
        out = []
        for i, row in enumerate(self.fuse_layers):
            y = xs[i]
            for j, f in enumerate(cast(nn.ModuleList, row)):
                if j == i:
                    continue
                z = f(xs[j])
                if j > i:
                    z = F.interpolate(z, size=xs[i].shape[-2:], mode="bilinear", align_corners=False)
                y = y + z
            out.append(F.relu(y))
        return out


class PnLCalibNet(nn.Module):
    """HRNetV2-W48 heatmap network of PnLCalib (keypoints or line extremities).

    ``forward`` takes a batch of RGB images ``(N, 3, H, W)`` in ``[0, 1]`` (H and
    W multiples of 32 avoid rounding in the strided branches) and returns
    ``(N, out_channels, H/2, W/2)`` heatmaps after ``final_activation``
    (softmax over channels, or an element-wise sigmoid).
    """

    def __init__(self, out_channels: int, final_activation: Literal["softmax", "sigmoid"]) -> None:
        super().__init__()
        if final_activation not in ("softmax", "sigmoid"):
            raise ValueError(f"final_activation must be 'softmax' or 'sigmoid', not {final_activation!r}")
        self.out_channels = out_channels
        self.final_activation = final_activation

        # Stem: two stride-2 3x3 convs (the raw conv1 output is the H/2 skip, then H/4).
        self.conv1 = nn.Conv2d(3, STEM_CHANNELS, kernel_size=3, stride=2, padding=1, bias=False)
        self.bn1 = _bn(STEM_CHANNELS)
        self.conv2 = nn.Conv2d(STEM_CHANNELS, STEM_CHANNELS, kernel_size=3, stride=2, padding=1, bias=False)
        self.bn2 = _bn(STEM_CHANNELS)
        self.relu = nn.ReLU(inplace=True)

        self.layer1 = nn.Sequential(
            Bottleneck(STEM_CHANNELS, 64), *(Bottleneck(256, 64) for _ in range(BLOCKS_PER_BRANCH - 1))
        )

        # Transitions: transition1 maps layer1 (256 @ H/4) to two branches; transition2/3
        # keep the existing branches (None) and add one branch from the lowest resolution.
        self.transition1 = nn.ModuleList(
            [_conv_bn_relu(256, WIDTHS[0], 1), nn.Sequential(_conv_bn_relu(256, WIDTHS[1], 2))]
        )
        self.stage2 = self._stage(2)
        self.transition2 = self._add_branch_transition(2)
        self.stage3 = self._stage(3)
        self.transition3 = self._add_branch_transition(3)
        self.stage4 = self._stage(4)

        hr_channels = sum(WIDTHS) + STEM_CHANNELS  # 720 + 64 = 784
        self.head = nn.Sequential(
            nn.Sequential(
                nn.Conv2d(hr_channels, hr_channels, kernel_size=1),
                _bn(hr_channels),
                nn.ReLU(inplace=True),
                nn.Conv2d(hr_channels, out_channels, kernel_size=1),
            )
        )

    @staticmethod
    def _stage(stage: int) -> nn.Sequential:
        widths = WIDTHS[:stage]
        return nn.Sequential(
            *(HighResolutionModule(widths, BLOCKS_PER_BRANCH) for _ in range(MODULES_PER_STAGE[stage - 2]))
        )

    @staticmethod
    def _add_branch_transition(stage: int) -> nn.ModuleList:
        """Transition after ``stage``: identity for its branches, one new strided branch."""
        layers: list[nn.Module | None] = [None] * stage
        layers.append(nn.Sequential(_conv_bn_relu(WIDTHS[stage - 1], WIDTHS[stage], 2)))
        # torch types the items as modules; None (the identity) keeps the checkpoint's indices
        return nn.ModuleList(layers)  # type: ignore[arg-type]

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """The 784-channel head input at half the input resolution."""
        skip = self.conv1(x)  # 64 @ H/2, taken before bn1 / ReLU
        x = self.relu(self.bn1(skip))
        x = self.relu(self.bn2(self.conv2(x)))
        x = self.layer1(x)

        xs = [t(x) for t in self.transition1]
        xs = self.stage2(xs)
        xs = xs + [self.transition2[-1](xs[-1])]
        xs = self.stage3(xs)
        xs = xs + [self.transition3[-1](xs[-1])]
        xs = self.stage4(xs)

        size = xs[0].shape[-2:]
        hr = torch.cat(
            [xs[0]] + [F.interpolate(t, size=size, mode="bilinear", align_corners=False) for t in xs[1:]], dim=1
        )
        hr = F.interpolate(hr, size=skip.shape[-2:], mode="nearest")  # the x2 upsampling
        return torch.cat([hr, skip], dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        logits = self.head(self.features(x))
        if self.final_activation == "softmax":
            return torch.softmax(logits, dim=1)
        return torch.sigmoid(logits)


def keypoint_net() -> PnLCalibNet:
    """The keypoint network: 57 keypoint heatmaps + background, softmax over channels."""
    return PnLCalibNet(KEYPOINT_CHANNELS, "softmax")


def line_net() -> PnLCalibNet:
    """The line network: 23 line-extremity heatmaps + all line bodies, element-wise sigmoid."""
    return PnLCalibNet(LINE_CHANNELS, "sigmoid")
