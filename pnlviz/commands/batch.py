"""The one batch runner of the commands that go over a dataset frame by frame (``calibrate``,
``detect``, ``labels``, ``export``): where the frames run (here, a local pool of worker
processes, or a dask cluster), the progress bar, Ctrl+C, the figures of the summary; and the
resume of an interrupted run into a journaled zip.

A command hands :func:`run_batch` a :class:`BatchJob`: a picklable object that works on a chunk
of frames with a worker-side state (a frame reader, a detector) that it builds in
:meth:`BatchJob.open_state`. Each worker process builds that state once and keeps it under
:meth:`BatchJob.state_key` (:func:`worker_state`): a new run (a new key), or weights changed on
disk, builds it again. The results come back to the command in this process, which writes them.

On a cluster (``--dask N``: a local cluster of N worker processes; ``--scheduler
tcp://HOST:PORT``: an existing one) the frames go out in chunks (``--chunk``, 32 by default) of
stems; the job is sent to each worker once, and a worker reads the data where it is (it must be
able to: a shared filesystem). Only stems go out and only results come back, which the command
writes exactly as a local run does (same members, same order, same bytes). A task that fails is
retried twice (a lost worker's tasks go to the others); a chunk that still fails is reported frame
by frame and the others go on.
"""

from __future__ import annotations

import argparse

import contextlib
import itertools
import sys
import threading
import time
import uuid
from collections.abc import Callable, Hashable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pnlviz.commands.common import int_at_least

__all__ = ["BatchJob", "BatchRun", "add_cluster_args", "cluster_client", "interrupted", "journaled_zip",
           "map_on_cluster", "on_cluster", "pool_size", "previous_run", "resume_zip", "run_batch", "worker_state"]

RETRIES = 2


# ----------------------------------------------------------------------------- the job
@dataclass
class BatchJob:
    """A batch command's work, sent to every worker: :meth:`run_chunk` on a list of items (stems)
    returns their results, in order. ``run``: new for every command run, so that a long-lived
    cluster does not work from what an earlier run read (its edits, its settings)."""

    run: str = field(default_factory=lambda: uuid.uuid4().hex, kw_only=True)

    def state_key(self) -> Hashable:
        """What the worker-side state is built from: it is built again when this changes."""
        return self.run

    def open_state(self) -> object:
        """The worker-side state (None: the job needs none); closed, if it has ``close``, when
        another key replaces it."""
        return None

    def run_chunk(self, state, items: list) -> list:
        raise NotImplementedError


_worker: dict = {}  # this process's worker-side state: {"key": BatchJob.state_key(), "state": ...}
_worker_lock = threading.Lock()


def _close(state) -> None:
    close = getattr(state, "close", None)
    if close is not None:
        close()


def worker_state(job: BatchJob):
    """This process's state for ``job``: built by ``job.open_state()`` the first time its key is
    seen, then kept until another key comes."""
    key = job.state_key()
    with _worker_lock:
        if "key" not in _worker or _worker["key"] != key:
            old = _worker.pop("state", None)
            _worker.clear()
            _close(old)
            _worker.update(key=key, state=job.open_state())
        return _worker["state"]


def run_chunk(job: BatchJob, items: list) -> list:
    """One task on a worker process: ``job`` on ``items`` with this process's state."""
    return job.run_chunk(worker_state(job), items)


_pool_job: list = []  # a pool worker's job, given once when the process starts


def _start_pool_worker(job: BatchJob) -> None:
    """Pool workers leave Ctrl+C to the main process (which keeps what was done) and get the job
    once, not with every task."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _pool_job[:] = [job]


def _pool_chunk(items: list) -> list:
    return run_chunk(_pool_job[0], items)


def _chunks(items: Sequence, size: int) -> Iterator[list]:
    for i in range(0, len(items), size):
        yield list(items[i:i + size])


# ----------------------------------------------------------------------------- the cluster
def add_cluster_args(p) -> None:
    g = p.add_argument_group("cluster (pip install 'pnlviz[dask]')")
    where = g.add_mutually_exclusive_group()
    where.add_argument("--dask", type=int_at_least(1, 1024), default=None, metavar="N",
                       help="run on a local dask cluster of N worker processes (1 thread each)")
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run on an existing dask cluster (its workers must read the data where it is)")
    g.add_argument("--chunk", type=int_at_least(1), default=32, metavar="K", help="frames per cluster task (default 32)")


def on_cluster(args) -> bool:
    """``--dask`` or ``--scheduler`` was given."""
    return getattr(args, "dask", None) is not None or getattr(args, "scheduler", None) is not None


@contextlib.contextmanager
def cluster_client(args) -> Iterator[Any]:
    """A ``distributed.Client`` for ``--dask`` / ``--scheduler`` (None without them); a clear
    error when dask is not installed or the scheduler cannot be reached."""
    if not on_cluster(args):
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SystemExit("error: --dask / --scheduler need dask: pip install 'pnlviz[dask]'") from None
    if args.chunk < 1:
        raise SystemExit("error: --chunk must be >= 1")
    if args.dask is not None:
        if args.dask < 1:
            raise SystemExit("error: --dask must be >= 1 worker")
        with LocalCluster(n_workers=args.dask, threads_per_worker=1, processes=True, dashboard_address=":0",
                          silence_logs=40) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        _knock(args.scheduler)
        client = Client(args.scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise SystemExit(f"error: --scheduler {args.scheduler}: cannot connect ({exc})") from None
    with client:
        yield client


def _knock(address: str) -> None:
    """Raise ``OSError`` at once when nothing listens at a ``tcp://HOST:PORT`` scheduler address
    (dask's client would retry a refused connection for its whole timeout, 20 s); other addresses
    are left to dask."""
    import socket
    from urllib.parse import urlsplit

    where = urlsplit(address)
    try:
        port = where.port
    except ValueError:  # not a port number: dask says what is wrong with the address
        return
    if where.scheme != "tcp" or not where.hostname or port is None:
        return
    socket.create_connection((where.hostname, port), timeout=5).close()


def map_on_cluster(client, fn: Callable, shared: object, items: Sequence, chunk: int,
                   failed: Callable[[object, str], object]) -> Iterator:
    """``fn(shared, chunk_of_items) -> [result, ...]`` over ``items`` in chunks on the cluster;
    yields the results of each chunk as it completes. ``shared`` is sent to the workers once. A
    chunk that fails after :data:`RETRIES` retries yields ``failed(item, message)`` for each of
    its items instead."""
    from distributed import as_completed

    data = client.scatter(shared, broadcast=True)
    futures = {}
    for part in _chunks(items, chunk):
        futures[client.submit(fn, data, part, retries=RETRIES, pure=False)] = part
    for future in as_completed(futures):
        part = futures[future]
        try:
            results = future.result()
        except Exception as exc:  # noqa: BLE001 - the task's error, whatever it was: reported per frame
            message = f"failed on the cluster after {RETRIES} retries: {type(exc).__name__}: {exc}"
            results = [failed(item, message) for item in part]
        yield from results


# ----------------------------------------------------------------------------- the run
@dataclass
class BatchRun:
    """What a run did: results handled, whether Ctrl+C stopped it, its wall time, and where it
    ran (``workers`` processes, on a cluster or not)."""

    done: int = 0
    interrupted: bool = False
    elapsed: float = 0.0
    workers: int = 1
    cluster: bool = False


def pool_size(workers: int | None) -> int:
    """``--workers``: 0 (or none) for every core, else at least 1."""
    import os

    return (os.cpu_count() or 1) if not workers else max(1, workers)


def _results(stack: contextlib.ExitStack, job: BatchJob, items: Sequence, args, run: BatchRun, processes: int,
             local_state, failed, chunk: int) -> Iterator:
    """The results of ``items``: on the cluster, in a pool of worker processes, or here."""
    client = stack.enter_context(cluster_client(args))
    if client is not None:
        run.cluster, run.workers = True, len(client.scheduler_info().get("workers", {}))
        return map_on_cluster(client, run_chunk, job, items, args.chunk, failed)
    if processes > 1 and len(items) > 1:
        import multiprocessing as mp

        run.workers = processes
        pool = stack.enter_context(mp.get_context("spawn").Pool(processes, initializer=_start_pool_worker,
                                                                 initargs=(job,)))
        size = max(1, min(8, len(items) // (4 * processes)))
        return itertools.chain.from_iterable(pool.imap(_pool_chunk, _chunks(items, size)))
    state = local_state
    if state is None:
        state = job.open_state()
        stack.callback(_close, state)
    return itertools.chain.from_iterable(job.run_chunk(state, part) for part in _chunks(items, chunk))


def run_batch(job: BatchJob, items: Sequence, handle: Callable[[Any], None], args, *, desc: str,
              processes: int = 1, local_state=None, failed: Callable[[Any, str], object] | None = None,
              chunk: int = 1, progress: bool = True) -> BatchRun:
    """``job`` over ``items``: on the cluster of ``args`` (``--dask`` / ``--scheduler``; ``failed``
    gives the result of an item whose task failed there), else in a local pool of ``processes``
    worker processes, else here, ``chunk`` items at a time (``local_state``: the job's state when
    this process has it already). Each result goes to ``handle`` in this process as it comes
    (from a pool in the items' order), under a progress bar. Ctrl+C stops the run: what was
    handled is kept, and the run says it was interrupted."""
    from tqdm import tqdm

    run = BatchRun()
    bar = tqdm(total=len(items), desc=desc, unit="frame", disable=not progress or None)
    t0 = time.perf_counter()
    try:
        with contextlib.ExitStack() as stack:
            for result in _results(stack, job, items, args, run, processes, local_state, failed, chunk):
                handle(result)
                run.done += 1
                bar.update()
    except KeyboardInterrupt:
        run.interrupted = True
    finally:
        bar.close()
    run.elapsed = time.perf_counter() - t0
    return run


@dataclass
class MapJob(BatchJob):
    """A module-level function over items (``fn(item)`` each), as a batch job: the work of the
    commands whose library function takes a runner (``synth``, ``eval``)."""

    fn: Callable[[Any], Any] | None = None

    def run_chunk(self, state, items: list) -> list:
        assert self.fn is not None
        return [self.fn(item) for item in items]


def map_items(fn: Callable[[Any], Any], items: Sequence, *, processes: int = 1, desc: str,
              progress: bool = True) -> list:
    """``fn(item)`` of every item, in order, through the batch runner (here, or in a pool of
    ``processes`` worker processes that leave Ctrl+C to this one), under its progress bar;
    KeyboardInterrupt when it was interrupted."""
    out: list = []
    run = run_batch(MapJob(fn=fn), list(items), out.append, argparse.Namespace(dask=None, scheduler=None), desc=desc,
                    processes=processes, progress=progress)
    if run.interrupted:
        raise KeyboardInterrupt
    return out


def interrupted(kept: int, total: int, out) -> int:
    """Ctrl+C: say what was kept; the exit status (130)."""
    print(f"interrupted: kept {kept} of {total} frames in {out}", file=sys.stderr)
    return 130


# ----------------------------------------------------------------------------- resume
def previous_run(out, resume: bool) -> dict:
    """``--resume``: the members an earlier run of this batch wrote into ``out`` (its zip and its
    journal, see :func:`pnlviz.data.zipwriter.resume_members`); the temporary files a killed run
    left beside ``out`` are removed. Without ``--resume``: {} (the run starts over), with a note
    when an interrupted run's journal is there."""
    from pnlviz.data.zipwriter import journal_path, resume_members

    out = Path(out)
    if not resume:
        if journal_path(out).is_file():
            print(f"note: an interrupted run left its progress in {journal_path(out).name}; starting over "
                  f"(--resume continues it)", file=sys.stderr)
        return {}
    done = resume_members(out)
    for stale in out.parent.glob(f".{out.name}.*.tmp"):
        stale.unlink(missing_ok=True)
    return done


def resume_zip(out: Path, resume: bool, stems: Sequence[str], member: Callable[[str], str],
               verb: str) -> tuple[dict[str, str], list[str]]:
    """A batch writing one zip member per frame (``member(stem)``): (the members an earlier run
    wrote for ``stems`` when ``resume``, the stems still to do), said in one line."""
    done = previous_run(out, resume)
    kept = {member(s): done[member(s)] for s in stems if member(s) in done}
    todo = [s for s in stems if member(s) not in kept]
    if resume:
        print(f"resuming: {len(kept)} of {len(stems)} frames already in {Path(out).name}, {len(todo)} to {verb}")
    return kept, todo


def journaled_zip(stack: contextlib.ExitStack, out: Path, key: Callable, kept: dict[str, str]):
    """The output zip of a batch (:class:`pnlviz.data.ZipStream`, journaled: a killed run leaves
    its progress for ``--resume``), holding what an earlier run finished (``kept``)."""
    from pnlviz.data import ZipStream

    out_zip = stack.enter_context(ZipStream(out, key=key, journal=True))
    for name, text in kept.items():
        out_zip.add(name, text)
    return out_zip
