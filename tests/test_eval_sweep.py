"""`lab eval identify`: the same per-job results on a real Dask cluster as on the local pool; a worker
killed mid-sweep costs its job only, and --resume completes it; bad input stops before anything runs."""

import json
import os
import signal
import threading
import time

import pytest

from lab.cli import main

pytest.importorskip("distributed")

# four short episodes: ideal sensing, the circle planner, one action, 12 s of sim time
SWEEP = ["--models", "1,2", "--seeds", "3-4", "--planners", "circle", "--mover", "static",
         "--max-actions", "1", "--max-time", "12", "--sensing", "ideal"]  # fmt: skip
VOLATILE = ("wall_time_s", "cpu_time_s", "real_time_factor", "real_time_factor_cpu", "loop_wall_time_s",
            "loop_cpu_time_s", "real_time_factor_wall", "real_time_factor_loop_cpu")  # fmt: skip


def _jobs(out):
    """Each job's JSON without what measures the machine (wall and CPU times, a decision's planning time)."""
    jobs = {}
    for p in sorted((out / "jobs").glob("*.json")):
        d = {k: v for k, v in json.loads(p.read_text()).items() if k not in VOLATILE}
        d["decisions"] = [{k: v for k, v in x.items() if k != "elapsed_s"} for x in d["decisions"]]
        jobs[p.stem] = d
    return jobs


@pytest.fixture
def cluster():
    import dask
    from dask.distributed import Client, LocalCluster

    # a job whose worker dies is failed at once (not handed to another worker), so the test sees it
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
            with Client(c) as client:
                yield c, client


def test_dask_cluster_gives_the_local_pools_results_and_survives_a_killed_worker(tmp_path, cluster):
    c, client = cluster
    local, dask_out = tmp_path / "local", tmp_path / "dask"
    assert main(["eval", "identify", *SWEEP[:3], "3", *SWEEP[4:], "--workers", "2", "--out", str(local)]) == 0
    assert main(["eval", "identify", *SWEEP[:3], "3", *SWEEP[4:], "--scheduler", c.scheduler_address,
                 "--out", str(dask_out)]) == 0  # fmt: skip
    a, b = _jobs(local), _jobs(dask_out)
    assert sorted(a) == ["circle_static_ideal_m1_s3", "circle_static_ideal_m2_s3"]
    assert a == b  # every field but the timings: same posteriors, actions, pose errors
    csv = (dask_out / "results.csv").read_text().splitlines()
    assert csv[0].startswith("key,true_model,planner,mover,sensing,seed") and len(csv) == 3

    # a sweep of 4 jobs on 2 workers; one worker is killed while it runs a job
    killed = tmp_path / "killed"
    rc = []
    t = threading.Thread(target=lambda: rc.append(main(
        ["eval", "identify", *SWEEP, "--scheduler", c.scheduler_address, "--out", str(killed)])))  # fmt: skip
    t.start()
    pids = client.run(os.getpid)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        busy = [w for w, keys in client.processing().items() if keys]
        if busy and any(k.startswith("lab-") for k in client.processing()[busy[0]]):
            break
        time.sleep(0.2)
    time.sleep(3.0)  # into the episode
    os.kill(pids[busy[0]], signal.SIGKILL)
    t.join(900)
    assert rc == [1]  # finished, with a failure
    failed = list((killed / "failed").glob("*.json"))
    assert failed and all("KilledWorker" in json.loads(p.read_text())["error"] for p in failed)
    assert len(failed) + len(list((killed / "jobs").glob("*.json"))) == 4
    rows = (killed / "results.csv").read_text().splitlines()[1:]
    assert len(rows) == 4 and sum("KilledWorker" in r for r in rows) == len(failed)
    client.wait_for_workers(2, timeout=120)  # the nanny restarted the killed one
    assert main(["eval", "identify", *SWEEP, "--scheduler", c.scheduler_address, "--out", str(killed),
                 "--resume"]) == 0  # fmt: skip
    assert not list((killed / "failed").glob("*.json")) and len(_jobs(killed)) == 4
    assert _jobs(killed)["circle_static_ideal_m1_s3"] == a["circle_static_ideal_m1_s3"]


def test_bad_sweeps_are_refused_in_one_line_before_anything_starts(tmp_path, capsys):
    out = tmp_path / "o"
    bad_file = tmp_path / "s.toml"
    bad_file.write_text('[sweep]\nmodels = [0, 1]\nplanner = ["lut"]\n')
    cases = [
        (["--seeds", "", "--out", str(out)], "the seed range is empty"),
        (["--sweep", str(bad_file), "--out", str(out)], "unknown field(s) planner; fields: models, seeds"),
        ([*SWEEP, "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)], "cannot reach the Dask scheduler"),
        ([*SWEEP, "--scheduler", "127.0.0.1:8786", "--out", str(out)], "--scheduler must be 'local' or"),
    ]
    for argv, msg in cases:
        assert main(["eval", "identify", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], err
        assert not out.exists()
