"""``pnlviz qa``: a dataset's suspect annotations, ranked. Every annotated frame is judged by the
engine (:func:`pnlviz.calib.qa.check_frame`: each class against the camera fitted without it, the
markings left out, the detections when given) and written as one JSON line, most suspect first,
with a summary line at the end. Frames are read as the app reads them
(:class:`pnlviz.pipeline.FrameReader`: an ``--edits`` folder's corrections apply) and run through
the one batch runner (:mod:`pnlviz.commands.batch`): worker processes or a dask cluster, a
progress bar, Ctrl+C keeps what was judged, ``--resume`` continues."""

from __future__ import annotations

import json
import math
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from pnlviz.commands.batch import BatchJob
from pnlviz.conventions import EVAL_SIZE
from pnlviz.commands.common import add_output_options, float_in, int_at_least, workers_arg


def add_qa_parser(sub) -> None:
    from pnlviz.commands.batch import add_cluster_args
    from pnlviz.commands.common import add_force_edits, parse_size

    p = sub.add_parser("qa", help="find the label errors: every frame's annotation judged, most suspect first",
                       description="Judge every annotated frame's lines against the camera fitted to the others "
                                   "(a class under the wrong name, off its paint, two markings in one class, a "
                                   "visible marking left out; detections that disagree with it) and write one "
                                   "JSON line per frame, sorted by score (higher: more likely wrong), then a "
                                   "summary line.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip (SoccerNet annotations)")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip to compare the annotation with")
    p.add_argument("--edits", type=Path, help="an edits folder of the app: its annotation corrections apply "
                                              "(read only)")
    add_force_edits(p)
    p.add_argument("--out", required=True, type=Path, help="output JSON lines file (e.g. qa.jsonl)")
    p.add_argument("--size", type=parse_size, default=EVAL_SIZE,
                   help="image size for frames without an image (default 960x540)")
    p.add_argument("--tol", type=float_in(0.0, 1000.0, open_low=True), default=None, metavar="PX",
                   help="a point this close to its marking sits on it (px at 960 wide; default 8)")
    p.add_argument("--no-priors", action="store_true",
                   help="faster: a frame with fewer than 4 keypoints is not calibrated from broadcast priors "
                        "(it is listed as without a camera)")
    p.add_argument("--top", type=int_at_least(0), default=10, metavar="N", help="frames listed at the end (default 10)")
    p.add_argument("--workers", type=workers_arg, default=1, help="worker processes (0: all cores)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run: frames already in --out (or in what a killed run left "
                        "beside it) are kept")
    add_cluster_args(p)
    add_output_options(p)
    p.set_defaults(func=run_qa)


@dataclass
class QAJob(BatchJob):
    """The frames' verdicts on any worker: the dataset (re-opened lazily where it runs), the
    detections, the fallback size, the engine's settings, the edits folder (None: none)."""

    ds: object
    predictions: object
    size: tuple[int, int]
    params: object
    edits: Path | None = None

    def open_state(self):
        from pnlviz.commands.calibrate import worker_reader
        from pnlviz.field import load_field_model

        return worker_reader(self.ds, self.predictions, self.size, "annotation", self.edits), load_field_model()

    def run_chunk(self, state, stems: list[str]) -> list:
        reader, model = state
        return [judge_stem(reader, stem, self.params, model) for stem in stems]


def judge_stem(reader, stem: str, params, model) -> dict:
    """One frame's JSON line: ``{"stem", "score", "findings", "ms"}``, or ``{"stem", "error"}``
    when it cannot be judged. Never raises."""
    from pnlviz.calib.qa import check_frame
    from pnlviz.commands.calibrate import frame_inputs

    try:
        inputs, problem = frame_inputs(reader, stem)
        if inputs is None or inputs.annotation is None:
            return {"stem": stem, "error": (problem or {}).get("failure", "no annotation")}
        qa = check_frame(inputs.annotation, inputs.size, inputs.detections, params, model)
        return {**qa.to_json(stem), "ms": round(qa.ms, 1)}
    except Exception as exc:  # noqa: BLE001 - one bad frame never stops the batch
        return {"stem": stem, "error": f"internal error: {type(exc).__name__}: {exc}"}


def _order(line: dict) -> tuple:
    """Most suspect first, frames that could not be judged after them, the summary last."""
    if "summary" in line:
        return (2, 0.0, "")
    if "error" in line:
        return (1, 0.0, line["stem"])
    return (0, -line["score"], line["stem"])


def previous_lines(out: Path, resume: bool) -> dict[str, dict]:
    """``--resume``: the frames an earlier run judged, from ``out`` and from what a killed run
    left beside it (its temporary file: whole lines only); those temporary files are removed."""
    if not resume:
        return {}
    done: dict[str, dict] = {}
    stale = sorted(out.parent.glob(f".{out.name}.*.tmp"))
    damaged = 0
    for path in ([out] if out.is_file() else []) + stale:
        with open(path, encoding="utf-8", errors="replace") as f:
            for text in f:
                try:
                    line = json.loads(text)
                except ValueError:
                    damaged += path == out  # a line torn by a kill is expected in the temporary file
                    continue
                if _judged(line):
                    done[line["stem"]] = line
                elif not (isinstance(line, dict) and ("summary" in line or "error" in line)):
                    damaged += 1
    for path in stale:
        path.unlink(missing_ok=True)
    if damaged:
        print(f"warning: {out}: {damaged} damaged line(s) not kept: their frames are judged again", file=sys.stderr)
    return done


def _judged(line) -> bool:
    """A line of a frame this command judged (``stem``, a finite ``score``, a list of findings)."""
    import math

    return (isinstance(line, dict) and isinstance(line.get("stem"), str) and "error" not in line
            and type(line.get("score")) in (int, float) and math.isfinite(line["score"])
            and isinstance(line.get("findings"), list))


class Summary:
    """What the run found: frames judged, flagged (score >= 1), findings by kind."""

    def __init__(self):
        self.judged = self.flagged = 0
        self.kinds: Counter[str] = Counter()
        self.errors: list[str] = []
        self.ms: list[float] = []
        self.top: list[tuple[float, str, str]] = []

    def add(self, line: dict) -> None:
        if "error" in line:
            self.errors.append(f"{line['stem']}: {line['error']}")
            return
        self.judged += 1
        self.flagged += line["score"] >= 1.0
        self.kinds.update(f["kind"] for f in line["findings"])
        if "ms" in line:
            self.ms.append(line["ms"])
        first = line["findings"][0]["message"] if line["findings"] else ""
        self.top.append((line["score"], line["stem"], first))

    def line(self, run) -> dict:
        return {"summary": {"frames": self.judged + len(self.errors), "judged": self.judged, "flagged": self.flagged,
                            "findings": dict(self.kinds.most_common()), "not_judged": len(self.errors),
                            "seconds": round(run.elapsed, 1), "workers": run.workers}}

    def print(self, run, n_todo: int, out: Path, top: int) -> None:
        print(f"judged {self.judged} frames in {run.elapsed:.1f} s ({1e3 * run.elapsed / max(1, n_todo):.1f} ms/frame "
              f"with {run.workers} worker(s)" + (" on the dask cluster" if run.cluster else "") + f") -> {out}")
        print(f"  {self.flagged} flagged (score >= 1); findings: "
              + (", ".join(f"{k} {n}" for k, n in self.kinds.most_common()) or "none"))
        for score, stem, message in sorted(self.top, key=lambda t: (-t[0], t[1]))[:max(0, top)]:
            if score >= 1.0:
                print(f"  {score:6.2f}  {stem}  {message}")
        for e in self.errors[:10]:
            print(f"  not judged: {e}", file=sys.stderr)


def _frames(ds, edits) -> list[str]:
    edited = {s for s in (edits.stems() if edits is not None else ()) if edits.get(s).get("annotation") is not None}
    return [s for s in ds.stems if ds.frame(s).has_annotation or s in edited]


def _params(args):
    from pnlviz.calib.qa import QAParams

    priors = not getattr(args, "no_priors", False)
    if args.tol is None:
        return QAParams(prior_search=priors)
    if not (math.isfinite(args.tol) and 0 < args.tol <= 100):
        raise SystemExit("error: --tol must be a number of pixels in (0, 100]")
    return QAParams(tol_px=args.tol, far_px=2 * args.tol, prior_search=priors)


def run_qa(args) -> int:
    from pnlviz.commands.batch import interrupted, pool_size, run_batch
    from pnlviz.commands.calibrate import frame_reader
    from pnlviz.commands.common import open_input_dataset, print_skipped, read_edits_folder
    from pnlviz.data import LineStream, check_output, read_predictions

    params = _params(args)
    check_output(args.out, inputs=[args.detections], datasets=[args.data, args.edits])
    ds = open_input_dataset(args.data)
    predictions = read_predictions(args.detections, on_error=lambda e: print_skipped([e])) if args.detections else None
    edits = read_edits_folder(args.edits, ds, args.force_edits) if args.edits is not None else None
    stems = _frames(ds, edits)
    if not stems:
        print(f"{args.data}: no annotated frame to judge", file=sys.stderr)
        return 1
    kept = {s: line for s, line in previous_lines(args.out, args.resume).items() if s in set(stems)}
    todo = [s for s in stems if s not in kept]
    if args.resume:
        print(f"resuming: {len(kept)} of {len(stems)} frames already judged in {args.out.name}, {len(todo)} to judge")
    job = QAJob(ds, predictions, tuple(args.size), params, None if args.edits is None else args.edits.resolve())
    from pnlviz.field import load_field_model

    local = (frame_reader(ds, predictions, tuple(args.size), "annotation", edits), load_field_model())
    summary = Summary()
    with LineStream(args.out) as out:
        def write(line: dict) -> None:
            out.add(json.dumps(line), key=_order(line))
            summary.add(line)

        for line in kept.values():
            write(line)
        run = run_batch(job, todo, write, args, desc="qa", processes=pool_size(args.workers),
                        local_state=local, failed=lambda s, m: {"stem": s, "error": m},
                        progress=not args.no_progress)
        if not run.interrupted:
            out.add(json.dumps(summary.line(run)), key=_order({"summary": 1}))
    if run.interrupted:
        return interrupted(summary.judged, len(stems), args.out)
    summary.print(run, len(todo), args.out, args.top)
    return 0 if summary.judged else 1

