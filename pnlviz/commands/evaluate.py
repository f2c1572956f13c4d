"""``pnlviz eval``: the SoccerNet calibration score of a camera zip, and the WC14 / TSWC homography
metrics. Bad files are reported one line each and skipped; they never stop the command."""

from __future__ import annotations

import argparse
import csv
import io
import os
import sys
from pathlib import Path
from pnlviz.commands.common import add_output_options, float_in, workers_arg

DESCRIPTION = """\
Score predicted cameras against SoccerNet-format line annotations exactly as the official
SoccerNet evaluator does (JaC@5/10/20, completeness CR, final score FS = CR x JaC@5, at 960x540),
and, with --homographies, the WC14/TS-WorldCup homography metrics (IoU part, IoU whole,
projection error in metres, reprojection error / image height). Bad annotations or cameras are
reported and skipped."""


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1280x720, got {text!r}") from None
    if not (w > 0 and h > 0):
        raise argparse.ArgumentTypeError(f"image size must be positive, got {text!r}")
    return w, h


def add_eval_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("eval", help="JaC/CR/FS of predicted cameras (official protocol); WC14 homography metrics",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gt", type=Path, help="ground-truth annotations: folder or zip of <stem>.json")
    p.add_argument("--pred", type=Path, help="predicted cameras: zip (or folder) of camera_<stem>.json")
    p.add_argument("--csv", type=Path, help="write per-frame results to this CSV file")
    p.add_argument("--thresholds", type=float_in(0.0, 1000.0, open_low=True), nargs="+", default=[5.0, 10.0, 20.0], metavar="PX",
                   help="distance thresholds in pixels at 960x540 (default: 5 10 20)")
    p.add_argument("--ignore-unknown", action="store_true",
                   help="drop 'Goal unknown'/'Line unknown' from the annotations (the official score counts "
                        "them as false negatives)")
    p.add_argument("--workers", type=workers_arg, default=1, help="worker processes (default 1)")
    p.add_argument("--homographies", type=Path, metavar="GT.json",
                   help="ground-truth template->image homographies (WC14/TSWC, 1280x720): also print the "
                        "homography metrics of --pred-homographies, or of the --pred cameras")
    p.add_argument("--pred-homographies", type=Path, metavar="PRED.json", help="predicted homographies, same format")
    p.add_argument("--camera-size", type=_size, metavar="WxH",
                   help="image size the --pred cameras were made for (default: twice their principal point); "
                        "used only to turn cameras into homographies")
    add_output_options(p)
    p.set_defaults(func=run_eval)
    return p


def _report(line: str) -> None:
    print(f"skipped: {line}", file=sys.stderr)


def _write_csv(path: Path, rows: list[dict]) -> None:
    from pnlviz.data import atomic_write_text

    buf = io.StringIO()
    if rows:
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        for row in rows:  # accuracies are float32 values: 7 significant digits print them exactly
            writer.writerow({k: (f"{v:.7g}" if isinstance(v, float) else v) for k, v in row.items()})
    atomic_write_text(path, buf.getvalue())


def _read_homographies_leniently(path: Path) -> dict:
    """``{stem: 3x3}`` from a JSON file; a malformed entry is reported and skipped."""
    from pnlviz.data import DataError
    from pnlviz.data.homographies import parse_homographies
    from pnlviz.data.jsonio import parse_json_bytes, read_file_bytes

    source = os.fspath(path)
    obj = parse_json_bytes(read_file_bytes(path), source)
    if not isinstance(obj, dict):
        return parse_homographies(obj, source)  # raises the one-line error
    out = {}
    for stem, value in obj.items():
        try:
            out.update(parse_homographies({stem: value}, source))
        except DataError as e:
            _report(str(e))
    return out


def _require_matches(args, summary, n_cameras: int) -> None:
    """DataError when there is nothing to score: no readable annotation, or no frame with a camera."""
    from pnlviz.data import DataError

    if not summary.n_frames:
        raise DataError(os.fspath(args.gt), "no annotation could be read: nothing to evaluate")
    if not summary.n_calibrated:
        raise DataError(os.fspath(args.pred), f"no camera matches a frame of {args.gt} ({summary.n_frames} "
                                              f"frames, {n_cameras} cameras read): nothing to evaluate")


def _args_problem(args) -> str | None:
    """What is wrong with the options together, in one line (None: nothing)."""
    if args.gt is None and args.homographies is None:
        return "give --gt (with --pred) and/or --homographies"
    if args.gt is not None and args.pred is None:
        return "--gt needs --pred (the predicted cameras)"
    if args.homographies is not None and args.pred_homographies is None and args.pred is None:
        return "--homographies needs --pred-homographies or --pred cameras"
    if any(t <= 0 for t in args.thresholds):
        return "thresholds must be positive"
    return None


def _eval_soccernet(args, gt, cameras: dict, progress: bool) -> None:
    """The SoccerNet score of ``cameras`` against the annotations of the dataset ``gt``
    (``--gt``), printed (and written to ``--csv``)."""
    from pnlviz.metrics.soccernet import evaluate_dataset

    from pnlviz.commands.batch import map_items

    workers = max(1, args.workers)
    summary = evaluate_dataset(gt, cameras, args.thresholds, progress=progress, count_unknown=not args.ignore_unknown,
                               run=lambda fn, chunks: map_items(fn, chunks, processes=workers, desc="eval",
                                                                progress=progress),
                               on_error=_report)
    _require_matches(args, summary, len(cameras))
    print(f"SoccerNet camera calibration (960x540): {args.gt} vs {args.pred}")
    print(summary.table())
    for split, part in summary.by_split().items():
        fs = f", FS {part.final_score:.4f}" if 5.0 in part.thresholds else ""
        jac = ", ".join(f"JaC@{t:g} {part.jac(t):.4f}" for t in part.thresholds)
        print(f"  split {split}: frames {part.n_frames}, CR {part.completeness:.4f}, {jac}{fs}")
    skipped = len(summary.skipped_annotations)
    if skipped:
        print(f"{skipped} annotation(s) skipped (not counted)")
    if summary.unmatched_cameras:
        print(f"{len(summary.unmatched_cameras)} camera(s) without an annotation (ignored)")
    if args.csv is not None:
        _write_csv(args.csv, summary.rows())
        print(f"wrote {args.csv} ({summary.n_frames} frames)")


def _eval_homographies(args, cameras: dict | None, progress: bool) -> None:
    """The WC14 homography metrics of ``--pred-homographies`` (else of the homographies of
    ``cameras``) against ``--homographies``, printed."""
    from pnlviz.data import DataError, read_homographies
    from pnlviz.metrics.homography import evaluate_homographies, homography_from_camera

    gt_h = read_homographies(args.homographies)
    if args.pred_homographies is not None:
        pred_h = _read_homographies_leniently(args.pred_homographies)
        what = args.pred_homographies
    else:
        pred_h = {}
        for stem, cam in (cameras or {}).items():  # --homographies without --pred-homographies has --pred
            try:
                pred_h[stem] = homography_from_camera(cam, source_size=args.camera_size)
            except (DataError, ValueError) as e:
                _report(f"camera_{stem}.json: {e}")
        what = args.pred
    if not any(stem in pred_h for stem in gt_h):
        raise DataError(os.fspath(what), f"no homography matches a frame of {args.homographies} "
                                         f"({len(gt_h)} frames, {len(pred_h)} homographies): nothing to evaluate")
    hs = evaluate_homographies(gt_h, pred_h, progress=progress)
    print(f"Homography metrics (1280x720 image, 115x74 yd template): {args.homographies} vs {what}")
    print(hs.table())


def run_eval(args) -> int:
    problem = _args_problem(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    if args.csv is not None:
        from pnlviz.data import check_output

        check_output(args.csv, inputs=[args.gt, args.pred, args.homographies, args.pred_homographies],
                     datasets=[args.gt], what="--csv")
    progress = not args.no_progress
    cameras = None
    gt = None
    if args.gt is not None:
        from pnlviz.commands.common import open_input_dataset

        gt = open_input_dataset(args.gt)
    if args.pred is not None:
        from pnlviz.data.cameras import read_cameras

        cameras, _ = read_cameras(args.pred, on_error=_report, splits=gt.splits if gt is not None else ())
    if gt is not None and cameras is not None:  # --gt comes with --pred
        _eval_soccernet(args, gt, cameras, progress)
    if args.homographies is not None:
        _eval_homographies(args, cameras, progress)
    return 0
