"""``pnlviz train``: train the light default detector (LightNet) on synthetic frames.

    pnlviz train [--config assets/models/light_config.json] [--out assets/models/light.pt]
                 [--frames N] [--epochs E] [--minutes M] [--cache DIR] [--no-progress]

``--frames`` / ``--epochs`` override the config (smoke runs); ``--minutes`` stops the training
loop cleanly at that time budget and still saves the checkpoint and its JSON sidecar.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pnlviz.detect.default import DEFAULT_MODEL as DEFAULT_OUT  # where pnlviz detect and the app look


def add_train_parser(subparsers) -> None:
    p = subparsers.add_parser("train", help="train the light default detector on synthetic frames (torch, CPU)",
                              description="Train LightNet (shared-trunk keypoint + line heatmap network) on "
                                          "synthetic frames rendered in memory; writes a plain state dict and a "
                                          "JSON provenance sidecar next to it.")
    p.add_argument("--config", type=Path, default=None,
                   help="training config JSON (default assets/models/light_config.json)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output checkpoint (default {DEFAULT_OUT})")
    p.add_argument("--frames", type=int, default=None, help="override the number of synthetic frames")
    p.add_argument("--epochs", type=int, default=None, help="override the number of epochs")
    p.add_argument("--minutes", type=float, default=None, help="stop training after this many minutes and save")
    p.add_argument("--batch-size", type=int, default=None, help="override the batch size")
    p.add_argument("--cache", type=Path, default=None, help="folder caching the rendered frames between runs")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default from the config)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_train)


def run_train(args) -> int:
    from pnlviz.detect.train import DEFAULT_CONFIG_PATH, load_config, train

    config_path = args.config if args.config is not None else DEFAULT_CONFIG_PATH
    try:
        config = load_config(config_path)
    except (OSError, ValueError) as exc:
        print(f"error: cannot read training config {config_path}: {exc}", file=sys.stderr)
        return 2
    for name, attr in (("frames", "frames"), ("epochs", "epochs"), ("batch_size", "batch_size"),
                       ("threads", "threads")):
        value = getattr(args, name, None)
        if value is not None:
            if value < 1:
                print(f"error: --{name.replace('_', '-')} must be >= 1", file=sys.stderr)
                return 2
            setattr(config, attr, int(value))
    if args.minutes is not None and args.minutes <= 0:
        print("error: --minutes must be > 0", file=sys.stderr)
        return 2
    result = train(config, args.out, minutes=args.minutes, progress=not args.no_progress, cache_dir=args.cache)
    note = " (stopped by --minutes)" if result.stopped_early else ""
    print(f"trained {result.epochs_done:.2f} epochs, {result.steps} steps in {result.seconds:.0f} s{note}; "
          f"final loss {result.final_loss:.6f} -> {result.path}")
    return 0
