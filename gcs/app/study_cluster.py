"""Where studies run: Dask distributed, on a LocalCluster or on the user's own cluster.

A study is a list of independent tasks (chunks of plants); each task's result depends only on
its arguments (its seeds are derived from the study's seed and the chunk's index), so the
results are the same whatever the number of workers, their order of completion, or a worker
that died and whose tasks the scheduler gave to another. ``workers = 0`` runs the tasks in this
process, without Dask: one after the other (``threads = 1``, for debugging), or on a pool of
threads (numpy's matrix products and FFTs release the GIL); :func:`place` decides, for the
commands' default, whether a local cluster would gain more than it costs to start.
"""

from __future__ import annotations

import logging
import os
import re
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

from gcs.errors import ClusterError

__all__ = [
    "Cluster",
    "Placement",
    "Task",
    "busy_cores",
    "check_scheduler",
    "machine_workers",
    "place",
    "connect",
    "finish_here",
    "run_tasks",
    "start_here",
]

#: ``tcp://HOST:PORT`` or ``tls://HOST:PORT``; HOST a name, an IPv4 or a bracketed IPv6 address.
_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):([0-9]{1,5})$")
#: Seconds to wait for a scheduler before saying it is unreachable.
CONNECT_TIMEOUT_S = 10.0
#: Seconds a LocalCluster costs before it computes anything: start the scheduler and the worker
#: processes, import gcs and numpy in each, and close them (measured on a 2-core machine,
#: docs/studies.md "In this process or on a local cluster").
LOCAL_CLUSTER_COST_S = 14.0
#: Times the scheduler may re-run a task whose worker died (Dask's own rescheduling aside).
RETRIES = 2


@dataclass(frozen=True)
class Cluster:
    """Where to run.

    Parameters
    ----------
    scheduler : str or None
        Address of a running scheduler (``tcp://HOST:PORT``); None starts a LocalCluster.
    workers : int or None
        LocalCluster size (one thread each); None: the cores this process may use (the
        commands first resolve None with :func:`place`: a cluster only when it pays); 0: no
        Dask, the tasks run in this process.
    connect_timeout_s : float
        Seconds to wait for the scheduler.
    blas_threads : int or None
        BLAS threads of each local worker; None: Dask's default, one. A result computed with
        large matrix products can differ in its last bits with the number of BLAS threads
        (the order of a sum); ``gcs montecarlo`` gives its workers the threads this process
        computes with, so that its rows are those computed in one process, bit for bit. The
        workers of a running cluster keep their own setting.
    threads : int
        With ``workers == 0``: threads of this process that run the tasks (1: one after the
        other). A task's result depends only on its arguments, not on the thread that runs it.
    """

    scheduler: str | None = None
    workers: int | None = None
    connect_timeout_s: float = CONNECT_TIMEOUT_S
    blas_threads: int | None = None
    threads: int = 1

    def describe(self) -> str:
        """One phrase for the terminal: where the work runs."""
        if self.scheduler is not None:
            return f"on the Dask scheduler at {self.scheduler}"
        if self.workers == 0:
            return "in this process" + (f" on {self.threads} threads" if self.threads > 1 else "")
        n = self.workers or machine_workers()
        return f"on a local Dask cluster of {n} worker{'s' if n != 1 else ''}"


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(*args)`` on a worker.

    Parameters
    ----------
    key : str
        Name (unique within a run; shown on the Dask dashboard).
    fn : callable
        An importable module-level function.
    args : tuple
        Its arguments (picklable).
    """

    key: str
    fn: Callable[..., Any]
    args: tuple


@dataclass(frozen=True)
class Placement:
    """Where a study runs, and why, in one line.

    Parameters
    ----------
    cluster : Cluster
        Where it runs (``workers`` resolved: 0, or the local cluster's size).
    line : str
        The decision in words, for the command's output.
    estimate_s : float or None
        The study's estimated computing time in this process [s]; None when the options
        decided (``--workers``, ``--scheduler``) and nothing was estimated.
    """

    cluster: Cluster
    line: str
    estimate_s: float | None = None


def place(
    cluster: Cluster,
    estimate_s: Callable[[], float],
    tasks: int,
    cores: int | None = None,
    cluster_cost_s: float | None = None,
    threads: bool = False,
    busy: float | None = None,
) -> Placement:
    """In this process or on a local cluster: a cluster only when the study gains from it.

    ``--workers`` or ``--scheduler`` given: obeyed, nothing estimated. Otherwise the study's
    computing time in this process, ``T = estimate_s()``, decides: shared among
    ``n = min(idle cores, tasks)`` local workers it would save ``T (1 - 1/n)``; a cluster starts
    only when that saving is more than the cluster's own cost (``LOCAL_CLUSTER_COST_S``). The
    idle cores are the cores less those other work keeps busy: a worker on a core that is
    already taken shares it and gains nothing, while the cluster's start-up still costs (at
    load 20 on 2 cores a local cluster took 623 s for a study that ran in 91 s here). What
    ``threads`` saves in this process is not counted (it depends on how much of a task holds
    the GIL): a study goes to a cluster only when the cluster pays even against one thread.

    Parameters
    ----------
    cluster : Cluster
        What the options describe.
    estimate_s : callable
        Returns the study's estimated computing time in this process [s] (called only when
        the options leave the choice open).
    tasks : int
        Independent tasks of the study (no more workers than tasks are useful).
    cores : int, optional
        Cores this process may use; default :func:`machine_workers`.
    cluster_cost_s : float, optional
        A local cluster's start-up cost [s]; default ``LOCAL_CLUSTER_COST_S``.
    threads : bool
        In this process, run the tasks on ``n`` threads (``Cluster.threads``) rather than one
        after the other: for tasks whose work releases the GIL (numpy's products and FFTs).
    busy : float, optional
        Cores kept busy by other work; default :func:`busy_cores` (the load average less this
        process).

    Returns
    -------
    Placement
    """
    if cluster.scheduler is not None or cluster.workers is not None:
        return Placement(cluster, cluster.describe() + " (as asked)")
    cost = LOCAL_CLUSTER_COST_S if cluster_cost_s is None else cluster_cost_s
    all_cores = cores if cores is not None else machine_workers()
    taken = busy_cores() if busy is None else max(0.0, float(busy))
    idle = max(1, all_cores - round(taken))
    n = max(1, min(idle, tasks))
    total = float(estimate_s())
    saving = total * (1.0 - 1.0 / n)
    if n >= 2 and saving > cost:
        local = replace(cluster, workers=n)
        return Placement(
            local,
            f"{local.describe()}: the study is long (est. {total:.0f} s in this process; "
            f"{n} workers save about {saving:.0f} s, a cluster costs about {cost:.0f} s to start)",
            total,
        )
    if n >= 2:
        why = f"{n} workers would save about {saving:.0f} s, a cluster costs about {cost:.0f} s"
        why += " to start"
    elif idle < min(all_cores, tasks):
        why = f"{all_cores} cores, about {taken:.0f} kept busy by other work: nothing to share"
    else:
        why = "one core or one task: nothing to share"
    here = replace(cluster, workers=0, threads=n if threads else 1)
    line = f"{here.describe()}: the study is short (est. {total:.1f} s; {why})"
    return Placement(here, line, total)


def check_scheduler(url: str) -> str:
    """Refuse what is not a scheduler's address.

    Parameters
    ----------
    url : str
        What the user gave to ``--scheduler``.

    Returns
    -------
    str
        The address.

    Raises
    ------
    ClusterError
        ``"--scheduler <url>: not a scheduler address ..."``.
    """
    m = _ADDRESS.match(url.strip())
    if not m or not 1 <= int(m.group(3)) <= 65535:
        raise ClusterError(
            f"--scheduler {url}: not a scheduler address; give tcp://HOST:PORT "
            "(what `dask scheduler` prints, default port 8786)"
        )
    return url.strip()


def busy_cores() -> float:
    """Cores kept busy by other work: the 1-minute load average less this process's own one.

    Returns
    -------
    float
        0 where the load average is not known.
    """
    try:
        return max(0.0, os.getloadavg()[0] - 1.0)
    except (AttributeError, OSError):  # not a Unix
        return 0.0


def machine_workers() -> int:
    """Workers of the default LocalCluster: the cores this process may run on.

    Returns
    -------
    int
    """
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return max(os.cpu_count() or 1, 1)


@contextmanager
def connect(cluster: Cluster) -> Iterator[Any]:
    """A Dask client for ``cluster`` (None when ``workers == 0``), closed on exit.

    Parameters
    ----------
    cluster : Cluster
        Where to run.

    Yields
    ------
    distributed.Client or None

    Raises
    ------
    ClusterError
        The scheduler did not answer within ``connect_timeout_s``.
    """
    if cluster.scheduler is None and cluster.workers == 0:
        yield None
        return
    from distributed import Client, LocalCluster

    if cluster.scheduler is not None:
        address = check_scheduler(cluster.scheduler)
        try:
            client = Client(address, timeout=cluster.connect_timeout_s)
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"--scheduler {address}: unreachable ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    import dask

    n = cluster.workers or machine_workers()
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    if cluster.blas_threads is not None:
        for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            environ[name] = cluster.blas_threads
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
        # no dashboard; the scheduler still serves its small HTTP interface, which would take
        # port 8787 and, when another study or a user's cluster has it, warn on the terminal:
        # on loopback, on a free port
        local = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR,
        )
    try:
        with Client(local) as client:
            yield client
    finally:
        local.close()


def start_here(pool: ThreadPoolExecutor, tasks: Sequence[Task]) -> dict[Future, Task]:
    """Submit ``tasks`` to a pool of threads of this process.

    Parameters
    ----------
    pool : concurrent.futures.ThreadPoolExecutor
        The threads.
    tasks : sequence of Task
        The work.

    Returns
    -------
    dict
        Each task's future -> the task.
    """
    return {pool.submit(t.fn, *t.args): t for t in tasks}


def finish_here(futures: dict[Future, Task], on_result: Callable[[Task, Any], None]) -> None:
    """``on_result(task, result)`` in the calling thread as each future of :func:`start_here`
    finishes (a task's exception is raised here, the tasks not yet started are cancelled).

    Parameters
    ----------
    futures : dict
        From :func:`start_here`.
    on_result : callable
        Called once per task, in the order they finish.
    """
    pending = set(futures)
    try:
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                on_result(futures[future], future.result())
    finally:
        for future in pending:
            future.cancel()


def run_tasks(
    client: Any,
    tasks: Sequence[Task],
    on_result: Callable[[Task, Any], None],
    threads: int = 1,
) -> None:
    """Run every task; ``on_result(task, result)`` in this process as each one finishes.

    Parameters
    ----------
    client : distributed.Client or None
        From :func:`connect`; None runs the tasks here: in order (``threads = 1``) or on
        ``threads`` threads of this process.
    tasks : sequence of Task
        The work.
    on_result : callable
        Called once per task, in the order they finish.
    threads : int
        Threads of this process when ``client`` is None (``Cluster.threads``).
    """
    if client is None and threads > 1 and len(tasks) > 1:
        with ThreadPoolExecutor(min(threads, len(tasks)), "gcs-task") as pool:
            finish_here(start_here(pool, tasks), on_result)
        return
    if client is None:
        for task in tasks:
            on_result(task, task.fn(*task.args))
        return
    from distributed import as_completed

    run = uuid.uuid4().hex[:8]
    futures = {
        client.submit(t.fn, *t.args, key=f"{t.key}-{run}", pure=False, retries=RETRIES): t
        for t in tasks
    }
    try:
        for future in as_completed(futures):
            on_result(futures[future], future.result())
    finally:
        client.cancel(list(futures))
