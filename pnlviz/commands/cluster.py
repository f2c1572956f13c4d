"""Batch commands on a dask cluster: ``--dask N`` (a local cluster of N worker processes) or
``--scheduler tcp://HOST:PORT`` (an existing one).

The frames go out in chunks (``--chunk``, 32 by default) of stems; a worker opens the dataset by its
path (it must be able to read it: a shared filesystem) and returns each frame's result, which the
command writes into its output exactly as a local run does (same members, same order, same
bytes). Only stems go out and only results come back. A task that fails is retried twice (a
lost worker's tasks go to the others); a chunk that still fails is reported frame by frame and
the others go on. The progress bar follows the chunks as they finish.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence

__all__ = ["add_cluster_args", "cluster_client", "map_on_cluster"]

RETRIES = 2


def add_cluster_args(p) -> None:
    g = p.add_argument_group("cluster (pip install -e \".[dask]\")")
    where = g.add_mutually_exclusive_group()
    where.add_argument("--dask", type=int, default=None, metavar="N",
                       help="run on a local dask cluster of N worker processes (1 thread each)")
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run on an existing dask cluster (its workers must read the data where it is)")
    g.add_argument("--chunk", type=int, default=32, metavar="K", help="frames per cluster task (default 32)")


@contextlib.contextmanager
def cluster_client(args) -> Iterator[object | None]:
    """A ``distributed.Client`` for ``--dask`` / ``--scheduler`` (None without them); a clear
    error when dask is not installed or the scheduler cannot be reached."""
    if getattr(args, "dask", None) is None and getattr(args, "scheduler", None) is None:
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SystemExit('error: --dask / --scheduler need dask: pip install -e ".[dask]"') from None
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
        client = Client(args.scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise SystemExit(f"error: --scheduler {args.scheduler}: cannot connect ({exc})") from None
    with client:
        yield client


def map_on_cluster(client, fn: Callable, shared: object, items: Sequence, chunk: int,
                   failed: Callable[[object, str], object]) -> Iterator:
    """``fn(shared, chunk_of_items) -> [result, ...]`` over ``items`` in chunks on the cluster;
    yields the results of each chunk as it completes. ``shared`` is sent to the workers once. A
    chunk that fails after :data:`RETRIES` retries yields ``failed(item, message)`` for each of
    its items instead."""
    from distributed import as_completed

    data = client.scatter(shared, broadcast=True)
    futures = {}
    for i in range(0, len(items), chunk):
        part = list(items[i:i + chunk])
        futures[client.submit(fn, data, part, retries=RETRIES, pure=False)] = part
    for future in as_completed(futures):
        part = futures[future]
        try:
            results = future.result()
        except Exception as exc:  # noqa: BLE001 - the task's error, whatever it was: reported per frame
            message = f"failed on the cluster after {RETRIES} retries: {type(exc).__name__}: {exc}"
            results = [failed(item, message) for item in part]
        yield from results
