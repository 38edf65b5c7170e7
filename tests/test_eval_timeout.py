"""A job that hangs past its wall-clock limit is recorded as failed with its error, and the sweep goes
on: in the local pool (interrupted in its worker) and on a real Dask cluster (its worker restarted)."""

import time

import pytest

from lab.eval.executor import DaskExecutor, Job, LocalPool


def nap(seconds: float) -> dict:
    """A job that sleeps (a hang, when longer than the limit), then reports what it slept."""
    time.sleep(seconds)
    return {"slept_s": seconds}


JOBS = [Job("hangs", nap, {"seconds": 120.0}), Job("quick", nap, {"seconds": 0.2}),
        Job("quick2", nap, {"seconds": 0.3})]  # fmt: skip


def _check(outcomes, limit_s):
    by = {o.job.key: o for o in outcomes}
    assert sorted(by) == ["hangs", "quick", "quick2"]
    assert by["hangs"].result is None and by["hangs"].error.startswith("JobTimeout: ")
    assert f"wall-clock limit of {limit_s:g} s" in by["hangs"].error
    assert by["hangs"].wall_time_s < 60.0  # stopped at its limit, not after its 120 s
    assert by["quick"].result == {"slept_s": 0.2} and by["quick"].error is None
    assert by["quick2"].result == {"slept_s": 0.3} and by["quick2"].error is None


def test_local_pool_stops_a_job_at_its_limit_and_goes_on():
    _check(list(LocalPool(2, job_timeout_s=1.5).run(JOBS)), 1.5)


def test_dask_stops_a_job_at_its_limit_restarts_its_worker_and_goes_on():
    pytest.importorskip("distributed")
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        ex = DaskExecutor(scheduler=c.scheduler_address, job_timeout_s=1.5)
        try:
            _check(list(ex.run(JOBS)), 1.5)
            # the worker that held the abandoned job was restarted: nothing of it still runs
            with Client(c) as client:
                client.wait_for_workers(2, timeout=60)
                threads = client.run(lambda: sorted(t.name for t in __import__("threading").enumerate()))
            assert not any("lab-job" in names for names in threads.values()), threads
            assert [o.result for o in ex.run(JOBS[1:2])] == [{"slept_s": 0.2}]  # and it works again
        finally:
            ex.close()
