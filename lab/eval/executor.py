"""One interface for running independent jobs: a local process pool, or a Dask cluster.

:func:`make_executor` picks one: ``scheduler="tcp://HOST:8786"`` connects to a running Dask cluster
(``dask scheduler`` / ``dask worker``, or ``dask-jobqueue`` on Slurm), ``workers=N`` with Dask
installed starts a local Dask cluster of N single-threaded worker processes, and otherwise the local
pool (:class:`LocalPool`) runs the jobs in ``N`` worker processes. Each worker process runs one job at
a time and each job opens (and closes) its own PyBullet ``DIRECT`` client: nothing is shared between
jobs. Dask is imported only here, and only when asked for (``pip install lab[cluster]``).

Scheduling, resubmission after a lost worker and retries are Dask's (futures, ``as_completed``,
``retries``), not ours. A job that raises, or whose worker dies, is reported as failed with its error
(:class:`Outcome`), and the others go on.

**A job's wall-clock limit** (``job_timeout_s``) is kept inside the worker, the same in both engines: a
job still running at its limit ends with :class:`JobTimeout`, recorded as its error. In a local pool's
worker the job runs in the process's main thread, and ``SIGALRM`` interrupts it (also in a sleep or a
wait); a Dask worker runs tasks in threads, so there the job runs in a thread of its own that the task
stops waiting for at the limit, and the executor then restarts that worker through its nanny
(``Client.restart_workers``), which ends the abandoned thread with its process. (A local pool's job
stuck inside one C call that never returns to Python is not interrupted: give such jobs to Dask.)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

from lab.errors import ConfigError

__all__ = ["DaskExecutor", "Job", "JobTimeout", "LocalPool", "Outcome", "make_executor"]

#: The default wall-clock limit of one job [s]: a hung job costs an hour, not the sweep.
JOB_TIMEOUT_S = 3600.0


@dataclass(frozen=True)
class Job:
    """One independent job: ``fn(**kwargs)``, named ``key`` (unique in its sweep). ``fn`` must be a
    module-level function (it is pickled by reference to the worker)."""

    key: str
    fn: Callable
    kwargs: dict


@dataclass(frozen=True)
class Outcome:
    """What became of a job: its result, or the error that ended it (``"Type: message"``)."""

    job: Job
    result: object | None
    error: str | None
    wall_time_s: float


class JobTimeout(Exception):
    """A job still running at its wall-clock limit. ``worker``: the Dask worker it was abandoned on
    (None in a local pool, where it was interrupted)."""

    def __init__(self, message: str, worker: str | None = None):
        super().__init__(message, worker)
        self.message, self.worker = message, worker

    def __str__(self) -> str:
        return self.message


def _with_alarm(fn, kwargs, timeout_s: float):
    """``fn(**kwargs)`` in this (main) thread, interrupted by ``SIGALRM`` at ``timeout_s``."""
    import signal

    def stop(signum, frame):
        raise JobTimeout(f"the job ran past its wall-clock limit of {timeout_s:g} s (--job-timeout)")

    old = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        return fn(**kwargs)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def _in_thread(fn, kwargs, timeout_s: float, worker: str | None):
    """``fn(**kwargs)`` in a thread of its own, waited for ``timeout_s`` at most (then abandoned)."""
    import threading

    box: dict = {}

    def target():
        try:
            box["out"] = fn(**kwargs)
        except BaseException as e:  # handed to the waiting thread
            box["err"] = e

    t = threading.Thread(target=target, name="lab-job", daemon=True)
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        raise JobTimeout(f"the job ran past its wall-clock limit of {timeout_s:g} s (--job-timeout)", worker)
    if "err" in box:
        raise box["err"]
    return box["out"]


def _timed(fn, kwargs, timeout_s: float | None = None, worker: str | None = None):
    """``(fn(**kwargs), wall time [s])`` in a worker, ended by :class:`JobTimeout` at ``timeout_s``."""
    import threading

    t0 = time.perf_counter()
    if timeout_s is None:
        out = fn(**kwargs)
    elif threading.current_thread() is threading.main_thread():
        out = _with_alarm(fn, kwargs, timeout_s)
    else:
        out = _in_thread(fn, kwargs, timeout_s, worker)
    return out, time.perf_counter() - t0


def _timed_on_dask(fn, kwargs, timeout_s: float | None = None):
    """:func:`_timed` in a Dask worker (which names itself in a :class:`JobTimeout`)."""
    from distributed import get_worker

    return _timed(fn, kwargs, timeout_s, get_worker().address)


def _check_timeout(timeout_s) -> float | None:
    if timeout_s is None:
        return None
    if not float(timeout_s) > 0:
        raise ConfigError(f"--job-timeout must be > 0 s, got {timeout_s!r}")
    return float(timeout_s)


def _one_blas_thread() -> None:
    import os

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


class LocalPool:
    """``workers`` processes of this machine (``spawn``ed: a fresh interpreter each, no PyBullet state
    inherited). A worker that dies breaks Python's pool: the jobs still pending are then reported as
    failed (``--resume`` runs them again)."""

    name = "local pool"

    def __init__(self, workers: int = 1, job_timeout_s: float | None = JOB_TIMEOUT_S):
        if int(workers) != workers or workers < 1:
            raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
        self.workers = int(workers)
        self.job_timeout_s = _check_timeout(job_timeout_s)

    def run(self, jobs: Sequence[Job]) -> Iterator[Outcome]:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_one_blas_thread) as pool:
            futs = {
                pool.submit(_timed, j.fn, j.kwargs, self.job_timeout_s): (j, time.perf_counter())
                for j in jobs
            }
            for f in as_completed(futs):
                job, t0 = futs[f]
                try:
                    res, wall = f.result()
                    yield Outcome(job, res, None, wall)
                except Exception as e:  # the job raised, or its worker died (BrokenProcessPool)
                    yield Outcome(job, None, f"{type(e).__name__}: {e}", time.perf_counter() - t0)

    def close(self) -> None:
        pass


def _probe(address: str, timeout_s: float) -> None:
    """Open (and close) a TCP connection to a ``tcp://HOST:PORT`` address: OSError when nothing listens."""
    import socket
    from urllib.parse import urlsplit

    if not address.startswith("tcp://"):
        return
    u = urlsplit(address)
    try:
        port = u.port
    except ValueError:
        port = None
    if u.hostname is None or port is None:
        raise ConfigError(f"--scheduler {address!r} needs a host and a port, like tcp://HOST:8786")
    with socket.create_connection((u.hostname, port), timeout=timeout_s):
        pass


class DaskExecutor:
    """Jobs as Dask futures on a cluster: ``scheduler`` (an address) or a local cluster of
    ``workers`` processes, one thread each. ``retries``: Dask re-runs a job that raised this many times;
    ``job_timeout_s``: a job's wall-clock limit (its worker is restarted when a job passes it)."""

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        retries: int = 0,
        connect_timeout_s: float = 10.0,
        job_timeout_s: float | None = JOB_TIMEOUT_S,
    ):
        self.job_timeout_s = _check_timeout(job_timeout_s)
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise ConfigError(
                "--scheduler and --workers need Dask: pip install 'lab[cluster]' (dask, distributed)"
            ) from None
        self.retries = int(retries)
        self.cluster = None
        if scheduler is not None:
            try:
                _probe(scheduler, connect_timeout_s)  # a refused port fails now, not after the timeout
                self.client = Client(scheduler, timeout=connect_timeout_s)
            except (OSError, TimeoutError) as e:
                raise ConfigError(
                    f"cannot reach the Dask scheduler at {scheduler!r} ({type(e).__name__}); start one with "
                    "`dask scheduler` and point --scheduler at the address it prints (tcp://HOST:8786)"
                ) from None
            self.name = f"Dask scheduler {scheduler}"
        else:
            self.cluster = LocalCluster(
                n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None
            )
            self.client = Client(self.cluster)
            self.name = f"local Dask cluster of {workers} workers"

    def run(self, jobs: Sequence[Job]) -> Iterator[Outcome]:
        from dask.distributed import as_completed

        futs = {}
        for j in jobs:
            # pure=False: a job is an experiment, never deduplicated; the key names it on the dashboard
            f = self.client.submit(
                _timed_on_dask,
                j.fn,
                j.kwargs,
                self.job_timeout_s,
                key=f"lab-{j.key}-{time.time_ns()}",
                pure=False,
                retries=self.retries,
            )
            futs[f] = (j, time.perf_counter())
        for f in as_completed(list(futs)):
            job, t0 = futs[f]
            try:
                res, wall = f.result()
                yield Outcome(job, res, None, wall)
            except JobTimeout as e:  # its thread still runs in the worker: restart the worker to end it
                yield Outcome(job, None, f"JobTimeout: {e}", time.perf_counter() - t0)
                if e.worker is not None:
                    self.client.restart_workers([e.worker], raise_for_error=False)
            except Exception as e:  # raised in the job, or KilledWorker (its worker died)
                yield Outcome(job, None, f"{type(e).__name__}: {e}", time.perf_counter() - t0)
            f.release()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(
    workers: int | None = None,
    scheduler: str | None = None,
    retries: int = 0,
    job_timeout_s: float | None = JOB_TIMEOUT_S,
):
    """``scheduler="tcp://HOST:8786"``: that Dask cluster; ``scheduler="local"``: a local Dask cluster of
    ``workers`` processes; no scheduler: the local pool of ``workers`` processes (default 1).
    ``job_timeout_s``: each job's wall-clock limit [s] (None: none)."""
    n = 1 if workers is None else workers
    if int(n) != n or n < 1:
        raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
    if retries < 0:
        raise ConfigError(f"--retries must be >= 0, got {retries}")
    job_timeout_s = _check_timeout(job_timeout_s)
    if scheduler == "local":
        return DaskExecutor(workers=int(n), retries=retries, job_timeout_s=job_timeout_s)
    if scheduler is not None:
        if not str(scheduler).startswith(("tcp://", "tls://", "ucx://")):
            raise ConfigError(
                f"--scheduler must be 'local' or an address like tcp://HOST:8786, got {scheduler!r}"
            )
        if workers is not None:
            raise ConfigError("--workers is for this machine; a --scheduler's cluster has the workers it has")
        return DaskExecutor(scheduler=scheduler, retries=retries, job_timeout_s=job_timeout_s)
    return LocalPool(int(n), job_timeout_s)
