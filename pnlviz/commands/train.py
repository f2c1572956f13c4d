"""``pnlviz train``: train the light default detector (LightNet) on synthetic and real frames.

    pnlviz train [--config F] [--out light.pt] [--init weights.pt | --init default]
                 [--data DIR ... | --data DIR --labels EXPORT] [--frames N] [--epochs E] [--minutes M] [--cache DIR] [--no-progress]
                 [--replace-default]

The config names the sources (synthetic frames, homography datasets, SoccerNet folders) and their
weights; ``--data`` replaces its real sources with the given folders (a folder holding a
``homographies.json`` is a homography dataset, anything else a SoccerNet-Calibration dataset);
``--labels`` trains on labels exported from the app, with the images of the one ``--data``.
``--init`` starts from a checkpoint (fine-tuning). ``--frames`` / ``--epochs`` override the config
(smoke runs); ``--minutes`` stops the training loop cleanly at that time budget and still saves
the checkpoint and its JSON sidecar. The shipped model is only written with ``--replace-default``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from pnlviz.detect.default import DEFAULT_MODEL  # where pnlviz detect and the app look
from pnlviz.commands.common import add_output_options

DEFAULT_OUT = Path("light.pt")


def add_train_parser(subparsers) -> None:
    p = subparsers.add_parser("train", help="train or fine-tune the light detector on synthetic and real frames",
                              description="Train LightNet (shared-trunk keypoint + line heatmap network) on "
                                          "synthetic frames rendered in memory and on real datasets (homography "
                                          "or SoccerNet-Calibration folders); writes a plain state dict and a "
                                          "JSON provenance sidecar next to it.")
    p.add_argument("--config", type=Path, default=None,
                   help="training config JSON (default: the config the shipped light model was trained with)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT,
                   help=f"output checkpoint (default ./{DEFAULT_OUT}; the shipped model only with --replace-default)")
    p.add_argument("--init", type=Path, default=None,
                   help="start from these LightNet weights, to fine-tune them: a model from an earlier pnlviz train, or "
                        "'default' for the shipped light model")
    p.add_argument("--data", type=Path, action="append", default=None, metavar="DIR",
                   help="a real training dataset replacing the config's (repeatable): a SoccerNet-Calibration "
                        "folder or zip with images and annotations, or an image folder with homographies.json")
    p.add_argument("--labels", type=Path, default=None, metavar="EXPORT",
                   help="labels exported from the app (pnlviz export folder or zip) for the images of the one --data "
                        "dataset: corrected keypoints are trained as corrected")
    p.add_argument("--data-weight", type=float, default=None,
                   help="share of each --data dataset in an epoch (default: the config's real share, split)")
    p.add_argument("--replace-default", action="store_true",
                   help=f"allow --out to be the shipped model {DEFAULT_MODEL}")
    p.add_argument("--frames", type=int, default=None, help="override the number of synthetic frames")
    p.add_argument("--epochs", type=int, default=None, help="override the number of epochs")
    p.add_argument("--minutes", type=float, default=None, help="stop training after this many minutes and save")
    p.add_argument("--batch-size", type=int, default=None, help="override the batch size")
    p.add_argument("--cache", type=Path, default=None, help="folder caching the rendered frames between runs")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default from the config)")
    add_output_options(p)
    p.set_defaults(func=run_train)


def run_train(args) -> int:
    from pnlviz.detect.default import torch_missing

    if (missing := torch_missing()) is not None:
        print(f"error: {missing}", file=sys.stderr)
        return 2

    from pnlviz.detect.train import train
    from pnlviz.detect.train_config import DEFAULT_CONFIG_PATH, load_config

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
    if args.minutes is not None and not (math.isfinite(args.minutes) and args.minutes > 0):
        print(f"error: --minutes must be a number > 0, got {args.minutes}", file=sys.stderr)
        return 2
    if _same_file(args.out, DEFAULT_MODEL) and not args.replace_default:
        print(f"error: --out {args.out} is the shipped default model; add --replace-default to overwrite it "
              f"(or choose another --out)", file=sys.stderr)
        return 2
    if args.init is not None and str(args.init) == "default" and not args.init.exists():
        args.init = DEFAULT_MODEL  # the shipped model, wherever the package is installed
    if args.init is not None and not args.init.is_file():
        print(f"error: --init {args.init}: no such file", file=sys.stderr)
        return 2
    from pnlviz.data.outputs import check_writable

    check_writable(args.out)  # a device, FIFO or link at --out, or a read-only folder: refused before training
    problem = _apply_data_args(args, config)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    try:
        result = train(config, args.out, minutes=args.minutes, progress=not args.no_progress, cache_dir=args.cache,
                       init=args.init)
    except (OSError, ValueError) as exc:  # DataError is a ValueError: a bad dataset or checkpoint
        from pnlviz.commands.common import os_error_line

        print(f"error: {os_error_line(exc) if isinstance(exc, OSError) else exc}", file=sys.stderr)
        return 2
    note = " (stopped by --minutes)" if result.stopped_early else ""
    print(f"trained {result.epochs_done:.2f} epochs, {result.steps} steps in {result.seconds:.0f} s{note}; "
          f"final loss {result.final_loss:.6f} -> {result.path}")
    return 0


def _same_file(a: Path, b: Path) -> bool:
    return Path(a).expanduser().resolve() == Path(b).resolve()


def _apply_data_args(args, config) -> str | None:
    """``--data`` / ``--labels`` / ``--data-weight``: the config's real sources replaced by them;
    the problem with them, if any."""
    if not args.data:
        return "--labels needs --data (the dataset the labels were made on)" if args.labels is not None else None
    missing = [d for d in args.data if not d.exists()]
    if missing:
        return f"--data {missing[0]}: no such folder or file"
    share = sum(float(r.get("weight", 1.0)) for r in config.real) or 1.0
    weight = args.data_weight if args.data_weight is not None else share / len(args.data)
    if not (math.isfinite(weight) and weight > 0):  # a relative weight: any finite positive number
        return f"--data-weight must be a finite number > 0, got {weight}"
    if args.labels is not None:
        if len(args.data) != 1:
            return "--labels goes with exactly one --data (the dataset the labels were made on)"
        config.real = [{"kind": "labels", "path": str(args.labels.resolve()), "images": str(args.data[0].resolve()),
                        "weight": weight}]
    else:
        config.real = [{"kind": "homography" if (d / "homographies.json").is_file() else "soccernet",
                        "path": str(d.resolve()), "weight": weight} for d in args.data]
    return None
