"""Detector speed on the CPU: ms per frame at 960x540 and peak memory, per network.

    python benchmarks/bench_detect.py [--size 960x540] [--threads 2] [--only NAME] [--full-warmup]

Rows (each measured in its own child process, so the peak resident memory is that network's):

* ``hrnet_kp``    the published keypoint network (HRNetV2-W48, 58 channels, softmax);
* ``hrnet_lines`` the published line network (24 channels, sigmoid);
* ``light``       LightNet, both heads from one trunk (one forward);
* ``light_detect`` LightNet through ``Detector.detect`` (resize + both heads + peak extraction);
* ``light_480``   LightNet at its training input size 480x272 (what ``light_detector`` uses).

Timing: one forward of a random frame after a warm-up (the published networks are warmed up at
320x192 to keep the whole benchmark under ~2 minutes; ``--full-warmup`` warms them at full size).
Random weights: speed does not depend on the values. Peak memory: ``ru_maxrss`` of the child.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

ROWS = ("hrnet_kp", "hrnet_lines", "light", "light_detect", "light_480")


def parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def measure(name: str, size: tuple[int, int], threads: int, full_warmup: bool) -> dict:
    import numpy as np
    import torch

    torch.set_num_threads(threads)
    torch.manual_seed(0)
    W, H = size
    if name.startswith("hrnet"):
        from pnlviz.detect.hrnet import keypoint_net, line_net

        net = (keypoint_net() if name == "hrnet_kp" else line_net()).eval()
        warm = (W, H) if full_warmup else (320, 192)
        params = sum(p.numel() for p in net.parameters())
        with torch.inference_mode():
            net(torch.rand(1, 3, warm[1], warm[0]))
            x = torch.rand(1, 3, H, W)
            t = time.perf_counter()
            net(x)
            dt = time.perf_counter() - t
    else:
        from pnlviz.detect.light import LightNet
        from pnlviz.detect.run import Detector

        net = LightNet().eval()
        params = sum(p.numel() for p in net.parameters())
        if name == "light_480":
            W, H = 480, 272
        if name == "light_detect":
            det = Detector.for_light_net(net, (W, H))
            img = (np.random.default_rng(0).random((540, 960, 3)) * 255).astype(np.uint8)
            det.detect([img])
            t = time.perf_counter()
            det.detect([img])
            dt = time.perf_counter() - t
        else:
            with torch.inference_mode():
                x = torch.rand(1, 3, H, W)
                net(x)
                t = time.perf_counter()
                net(x)
                dt = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB -> MiB on Linux
    return {"name": name, "size": f"{W}x{H}", "ms": 1e3 * dt, "peak_mib": peak, "params": params}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=parse_size, default=(960, 540))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--only", choices=ROWS, help="measure one row in this process (used by the parent)")
    ap.add_argument("--full-warmup", action="store_true", help="warm the published networks up at full size")
    args = ap.parse_args(argv)
    if args.only:
        print(json.dumps(measure(args.only, args.size, args.threads, args.full_warmup)))
        return 0
    t0 = time.perf_counter()
    print(f"torch threads {args.threads}, input {args.size[0]}x{args.size[1]} (one forward after a warm-up)")
    print(f"{'network':<14} {'input':>9} {'ms/frame':>10} {'peak MiB':>9} {'params':>11}")
    for name in ROWS:
        cmd = [sys.executable, __file__, "--only", name, "--size", f"{args.size[0]}x{args.size[1]}",
               "--threads", str(args.threads)] + (["--full-warmup"] if args.full_warmup else [])
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            print(f"{name:<14} failed: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        print(f"{r['name']:<14} {r['size']:>9} {r['ms']:>10.0f} {r['peak_mib']:>9.0f} {r['params']:>11,}")
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
