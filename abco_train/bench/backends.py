"""Where the cells of an ``abco bench`` grid run: local processes or a Ray cluster.

A backend takes the work function (:func:`abco_train.bench.grid.run_cell`), the cells' configs and
the plugins every worker imports, and yields ``(task index, outcome)`` as cells finish: the
work function's row, or the exception that killed its worker. It knows nothing of grids,
results files or configs; the grid runner (:mod:`abco_train.bench.grid`) owns those.

* ``local`` (default): parallel processes (:class:`concurrent.futures.ProcessPoolExecutor`,
  spawn context, one fresh process per cell; on Python 3.10, which cannot ask for that, a
  worker may run several cells in turn, each seeded on its own).
* ``ray``: the same cells as Ray tasks (``pip install abco[ray]``), joining the cluster at
  ``address`` or starting a local Ray instance, each task asking for its cell's threads as
  CPUs.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Generator, Sequence
from typing import Any

__all__ = ["BACKENDS", "BackendError", "run_local", "run_ray", "available_cores"]

BACKENDS = ("local", "ray")

Work = Callable[[dict[str, Any], tuple[str, ...]], dict[str, Any]]
Outcome = Generator[tuple[int, "dict[str, Any] | BaseException"], None, None]


class BackendError(RuntimeError):
    """A backend cannot start (e.g. Ray is not installed)."""


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def run_local(work: Work, tasks: list[dict[str, Any]], plugins: Sequence[str], jobs: int
              ) -> Outcome:  # fmt: skip
    """Run ``work(task, plugins)`` for every task in ``jobs`` fresh spawned processes."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = multiprocessing.get_context("spawn")
    if sys.version_info >= (3, 11):
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, max_tasks_per_child=1)
    else:  # Python 3.10 has no max_tasks_per_child: a worker process may run several cells
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx)
    try:
        futures = {pool.submit(work, t, tuple(plugins)): i for i, t in enumerate(tasks)}
        for future in as_completed(futures):
            try:
                yield futures[future], future.result()
            except Exception as exc:  # the worker process died
                yield futures[future], exc
    finally:  # closed early (an error, an interrupt): the cells not started never start
        pool.shutdown(wait=True, cancel_futures=True)


def run_ray(work: Work, tasks: list[dict[str, Any]], plugins: Sequence[str], jobs: int | None,
            address: str | None) -> Outcome:  # fmt: skip
    """Run ``work(task, plugins)`` for every task as Ray tasks, ``jobs`` at once at most."""
    try:
        import ray
    except ImportError:
        raise BackendError("--backend ray needs ray: pip install 'abco[ray]'") from None
    started = not ray.is_initialized()
    if started:
        try:
            if address:
                ray.init(address=address, logging_level=logging.WARNING)
            else:
                ray.init(num_cpus=available_cores(), include_dashboard=False,
                         logging_level=logging.WARNING)  # fmt: skip
        except Exception as exc:  # Ray's own errors: no cluster there, a node that never starts
            why = " ".join(str(exc).split())[:300]
            raise BackendError(f"Ray could not start ({type(exc).__name__}: {why})") from None
    try:
        pending: dict[Any, int] = {}
        remotes: dict[int, Any] = {}  # one remote function per CPU request
        queue = list(range(len(tasks)))
        limit = jobs or len(tasks)
        while queue or pending:
            while queue and len(pending) < limit:
                i = queue.pop(0)
                cpus = int(tasks[i]["threads"])
                if cpus not in remotes:
                    remotes[cpus] = ray.remote(num_cpus=cpus, max_retries=0)(work)
                pending[remotes[cpus].remote(tasks[i], tuple(plugins))] = i
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                try:
                    yield i, ray.get(ref)
                except Exception as exc:  # the task's worker died
                    yield i, exc
    finally:
        if started:
            ray.shutdown()
