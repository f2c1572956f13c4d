"""What the light model is trained against: CenterNet's penalty-reduced focal loss on its
probability maps (or the paper's masked MSE), and the photometric batch augmentations."""

from __future__ import annotations

import torch

from pnlviz.detect.light import LightNet

__all__ = ["augment", "focal_heatmap_loss", "loss_fn", "masked_mse", "peak_pixels"]


def augment(x: torch.Tensor, params: dict, gen: torch.Generator) -> torch.Tensor:
    """Colour jitter + Gaussian noise on an RGB batch in [0, 1] (B, 3, H, W)."""
    B = x.shape[0]

    def factor(name):
        a = float(params.get(name, 0.0))
        return 1.0 + (torch.rand(B, 1, 1, 1, generator=gen) * 2 - 1) * a

    if params.get("brightness"):
        x = x * factor("brightness")
    if params.get("contrast"):
        mean = x.mean(dim=(1, 2, 3), keepdim=True)
        x = (x - mean) * factor("contrast") + mean
    if params.get("saturation"):
        gray = (0.299 * x[:, 0:1] + 0.587 * x[:, 1:2] + 0.114 * x[:, 2:3])
        x = (x - gray) * factor("saturation") + gray
    if params.get("gain"):
        g = float(params["gain"])
        x = x * (1.0 + (torch.rand(B, 3, 1, 1, generator=gen) * 2 - 1) * g)
    if params.get("noise"):
        std = torch.rand(B, 1, 1, 1, generator=gen) * float(params["noise"])
        x = x + torch.randn(x.shape, generator=gen) * std
    return x.clamp_(0.0, 1.0)



def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean over the kept (B, C) channels of the per-channel mean squared error."""
    per_channel = (pred - target).square().mean(dim=(2, 3))
    return (per_channel * mask).sum() / mask.sum().clamp_min(1.0)


def peak_pixels(target: torch.Tensor, floor: float = 0.5) -> torch.Tensor:
    """The positives of the focal loss: pixels that are the 3x3 maximum of a target Gaussian
    reaching ``floor`` (one pixel per Gaussian, the one nearest its sub-pixel centre)."""
    return (target >= torch.nn.functional.max_pool2d(target, 3, 1, 1)) & (target >= floor)


def focal_heatmap_loss(p: torch.Tensor, log_p: torch.Tensor, log_1mp: torch.Tensor, target: torch.Tensor,
                       mask: torch.Tensor, pos: torch.Tensor, alpha: float = 2.0, beta: float = 4.0
                       ) -> torch.Tensor:
    """CenterNet's penalty-reduced pixel-wise focal loss (Law & Deng 2018, Zhou et al. 2019) on
    probability maps ``p`` (B, C, h, w), with their logs given for numerical stability: positives
    ``pos`` pull p to 1, every other pixel pushes p to 0 with weight (1 - target)^beta (so the
    Gaussian's shoulders are barely penalised); summed over kept channels, divided by the number of
    positives. Unlike a plain MSE it cannot be minimised by an empty map (issue #5: the MSE run
    collapsed to the background)."""
    m = mask[:, :, None, None]
    pos_f = pos.to(p.dtype) * m
    pos_loss = -((1 - p) ** alpha * log_p * pos_f).sum()
    neg_w = (1 - target).clamp_min(0) ** beta * (1 - pos.to(p.dtype)) * m
    neg_loss = -((p ** alpha) * log_1mp * neg_w).sum()
    return (pos_loss + neg_loss) / pos_f.sum().clamp_min(1.0)


def loss_fn(net: LightNet, x, kp_t, kp_m, ln_t, ln_m, kind: str = "focal") -> torch.Tensor:
    kp_logits, ln_logits = net.logits(x)
    if kind == "mse":
        return (masked_mse(torch.softmax(kp_logits, dim=1), kp_t, kp_m)
                + masked_mse(torch.sigmoid(ln_logits), ln_t, ln_m))
    if kind != "focal":
        raise ValueError(f"unknown loss {kind!r} (focal or mse)")
    # keypoints: the 57 keypoint channels of the softmax (the background is their complement)
    log_sm = torch.log_softmax(kp_logits, dim=1)[:, :-1]
    p = log_sm.exp()
    log_1mp = torch.log1p(-p.clamp(max=1 - 1e-6))
    kp_t, kp_m = kp_t[:, :-1], kp_m[:, :-1]
    kp_loss = focal_heatmap_loss(p, log_sm, log_1mp, kp_t, kp_m, peak_pixels(kp_t))
    # lines: the 23 extremity channels (two peaks each), and the line-body ridge channel as its own
    # term. Normalised together, the body's hundreds of ridge pixels per frame outnumbered the ~2
    # positives per extremity channel and starved those channels (issue #5: line-end peaks reached
    # 0.29 on average, 4 % above the 0.6 threshold).
    sig = torch.nn.functional.logsigmoid
    z, t, m = ln_logits[:, :-1], ln_t[:, :-1], ln_m[:, :-1]
    ln_loss = focal_heatmap_loss(torch.sigmoid(z), sig(z), sig(-z), t, m, peak_pixels(t))
    z, t, m = ln_logits[:, -1:], ln_t[:, -1:], ln_m[:, -1:]
    ln_loss = ln_loss + focal_heatmap_loss(torch.sigmoid(z), sig(z), sig(-z), t, m, t >= 0.8)
    return kp_loss + ln_loss
