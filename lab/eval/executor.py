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
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

from lab.errors import ConfigError

__all__ = ["DaskExecutor", "Job", "LocalPool", "Outcome", "make_executor"]


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


def _timed(fn, kwargs):
    t0 = time.perf_counter()
    out = fn(**kwargs)
    return out, time.perf_counter() - t0


def _one_blas_thread() -> None:
    import os

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


class LocalPool:
    """``workers`` processes of this machine (``spawn``ed: a fresh interpreter each, no PyBullet state
    inherited). A worker that dies breaks Python's pool: the jobs still pending are then reported as
    failed (``--resume`` runs them again)."""

    name = "local pool"

    def __init__(self, workers: int = 1):
        if int(workers) != workers or workers < 1:
            raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
        self.workers = int(workers)

    def run(self, jobs: Sequence[Job]) -> Iterator[Outcome]:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_one_blas_thread) as pool:
            futs = {pool.submit(_timed, j.fn, j.kwargs): (j, time.perf_counter()) for j in jobs}
            for f in as_completed(futs):
                job, t0 = futs[f]
                try:
                    res, wall = f.result()
                    yield Outcome(job, res, None, wall)
                except Exception as e:  # the job raised, or its worker died (BrokenProcessPool)
                    yield Outcome(job, None, f"{type(e).__name__}: {e}", time.perf_counter() - t0)

    def close(self) -> None:
        pass


class DaskExecutor:
    """Jobs as Dask futures on a cluster: ``scheduler`` (an address) or a local cluster of
    ``workers`` processes, one thread each. ``retries``: Dask re-runs a job that raised this many times."""

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        retries: int = 0,
        connect_timeout_s: float = 10.0,
    ):
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
                _timed, j.fn, j.kwargs, key=f"lab-{j.key}-{time.time_ns()}", pure=False, retries=self.retries
            )
            futs[f] = (j, time.perf_counter())
        for f in as_completed(list(futs)):
            job, t0 = futs[f]
            try:
                res, wall = f.result()
                yield Outcome(job, res, None, wall)
            except Exception as e:  # raised in the job, or KilledWorker (its worker died)
                yield Outcome(job, None, f"{type(e).__name__}: {e}", time.perf_counter() - t0)
            f.release()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(workers: int | None = None, scheduler: str | None = None, retries: int = 0):
    """``scheduler="tcp://HOST:8786"``: that Dask cluster; ``scheduler="local"``: a local Dask cluster of
    ``workers`` processes; no scheduler: the local pool of ``workers`` processes (default 1)."""
    n = 1 if workers is None else workers
    if int(n) != n or n < 1:
        raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
    if scheduler == "local":
        return DaskExecutor(workers=int(n), retries=retries)
    if scheduler is not None:
        if not str(scheduler).startswith(("tcp://", "tls://", "ucx://")):
            raise ConfigError(
                f"--scheduler must be 'local' or an address like tcp://HOST:8786, got {scheduler!r}"
            )
        return DaskExecutor(scheduler=scheduler, retries=retries)
    return LocalPool(int(n))
