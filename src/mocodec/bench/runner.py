"""Run independent tasks on the local cores or on a Dask cluster, with a progress bar.

``execute(fn, tasks, jobs=...)`` yields ``(task, result)`` as tasks finish, in any order: with
one job in this process, with several in a process pool, or on Dask workers
(``scheduler="tcp://host:port"``, or ``dask=True`` for a LocalCluster of ``jobs`` workers).
``fn`` must be a module-level function so workers can import it. A task whose worker raised
yields the exception as its result, so one bad clip never stops a run.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, TypeVar

from mocodec.errors import MocodecError
from mocodec.extras import require


def default_jobs() -> int:
    """All the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _progress(total: int, show: bool, what: str):
    tqdm = require("tqdm", "bench", "the progress bar").tqdm
    return tqdm(total=total, disable=not show, file=sys.stderr, unit=what, dynamic_ncols=True)


Task = TypeVar("Task")


def execute(
    fn: Callable[[Task], Any],
    tasks: Sequence[Task],
    jobs: int | None = None,
    scheduler: str | None = None,
    dask: bool = False,
    progress: bool = False,
    what: str = "task",
) -> Iterator[tuple[Task, Any]]:
    """``(task, fn(task) or the exception it raised)`` for every task, as they finish."""
    if jobs is not None and jobs < 1:
        raise MocodecError(f"jobs must be at least 1, got {jobs}")
    jobs = jobs or default_jobs()
    with _progress(len(tasks), progress, what) as bar:
        if scheduler or dask:
            results = _on_dask(fn, tasks, jobs, scheduler)
        elif jobs == 1 or len(tasks) <= 1:
            results = ((t, _called(fn, t)) for t in tasks)
        else:
            results = _on_pool(fn, tasks, jobs)
        for task, result in results:
            bar.update(1)
            yield task, result


def _called(fn: Callable, task):
    try:
        return fn(task)
    except Exception as e:  # noqa: BLE001 - reported per task by the caller
        return e


def _on_pool(fn: Callable, tasks: Sequence, jobs: int) -> Iterator:
    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks))) as pool:
        futures = {pool.submit(fn, t): t for t in tasks}
        for future in as_completed(futures):
            exc = future.exception()
            yield futures[future], exc if exc is not None else future.result()


def _on_dask(fn: Callable, tasks: Sequence, jobs: int, scheduler: str | None) -> Iterator:
    distributed = require("dask.distributed", "bench", "a run on Dask")
    Client, LocalCluster, dask_completed = distributed.Client, distributed.LocalCluster, distributed.as_completed
    cluster = None if scheduler else LocalCluster(n_workers=jobs, threads_per_worker=1, dashboard_address=None)
    try:
        try:
            client = Client(scheduler or cluster, timeout="20s")
        except OSError as e:
            raise MocodecError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
        with client:
            futures = client.map(fn, list(tasks), pure=False)
            owner = {f.key: t for f, t in zip(futures, tasks)}
            for future in dask_completed(futures):
                try:
                    result = future.result()
                except Exception as e:  # noqa: BLE001 - reported per task by the caller
                    result = e
                yield owner[future.key], result
    finally:
        if cluster is not None:
            cluster.close()
