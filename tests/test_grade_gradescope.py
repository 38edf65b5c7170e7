"""The Gradescope bundle (issue 47), graded as Gradescope would: unpacked into a stand-in for
/autograder, set up and run as root with CAP_SYS_ADMIN dropped and bubblewrap unusable (a default Docker
container forbids namespaces), so the uid mode grades. The reference solution scores 100 %, the template
0 %, and every attack of tests/test_grade_attacks.py no more than the template; run_autograder leaves a
results.json even when grading itself fails.
"""

import json
import os
import shutil
import socket
import subprocess
import sys
import zipfile

import pytest
from grade_modes import require
from test_grade_attacks import every_attack

from lab.cli import main
from lab.grading import get_assignment

EKF = get_assignment("ekf")


def _docker_like(cmd: list[str]) -> list[str]:
    """``cmd`` as root without CAP_SYS_ADMIN (setpriv) and, where bubblewrap is installed, with it hidden
    (a bind mount of /dev/null over it in a mount namespace of this command's own)."""
    inner = ["setpriv", "--bounding-set", "-sys_admin", "--inh-caps", "-sys_admin", *cmd]
    bwrap = shutil.which("bwrap")
    if bwrap is None:
        return inner
    return ["unshare", "-m", "sh", "-c", f'mount --bind /dev/null "{bwrap}" && exec "$@"', "sh", *inner]


@pytest.fixture(scope="module")
def autograder(tmp_path_factory):
    """The bundle of ekf, built, unpacked into ROOT/source and set up; returns ROOT and the env."""
    if (
        sys.platform != "linux"
        or os.geteuid() != 0
        or not shutil.which("setpriv")
        or not shutil.which("unshare")
    ):
        pytest.skip("needs root on Linux with setpriv and unshare (util-linux): the bundle's root grader")
    if shutil.which("uv") is None:
        pytest.skip("needs uv to pin the bundle's versions from uv.lock: pip install uv")
    require("uid")  # the bundle grades in the uid mode: its child must be able to run this Python
    tmp = tmp_path_factory.mktemp("gradescope")
    bundle = tmp / "autograder.zip"
    assert main(["assignments", "gradescope", "ekf", "--out", str(bundle), "--quiet"]) == 0
    root = tmp / "autograder"
    with zipfile.ZipFile(bundle) as z:
        names = set(z.namelist())
        z.extractall(root / "source")
    assert {"setup.sh", "run_autograder", "requirements.txt", "lab/__init__.py"} <= names
    assert "assignments/ekf/hidden_tests.py" in names
    for name in ("setup.sh", "run_autograder"):
        (root / "source" / name).chmod(0o755)
    shipped = (root / "source" / "assignments" / "ekf" / "ekf.py").read_text()
    assert shipped != EKF.module_path.read_text() and "BEGIN SOLUTION" not in shipped  # the template
    reqs = (root / "source" / "requirements.txt").read_text()
    assert "numpy==" in reqs and "scipy==" in reqs  # pinned from uv.lock
    env = {**os.environ, "AUTOGRADER_ROOT": str(root), "LAB_AUTOGRADER_PYTHON": sys.executable}
    env.pop("LAB_GRADE_SANDBOX", None)
    setup = _docker_like(["bash", str(root / "source" / "setup.sh")])
    r = subprocess.run(setup, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "sandbox: uid" in r.stdout and "WARNING uid mode cannot stop the network" in r.stdout
    return root, env


def _grade(autograder, put) -> dict:
    """Put a submission into ROOT/submission (``put(folder)``), run run_autograder, read results.json."""
    root, env = autograder
    sub = root / "submission"
    shutil.rmtree(sub, ignore_errors=True)
    sub.mkdir()
    put(sub)
    run = root / "source" / "run_autograder"
    r = subprocess.run(_docker_like([str(run)]), env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads((root / "results" / "results.json").read_text())


def _source(text: str):
    return lambda sub: (sub / "ekf.py").write_text(text)


def test_the_reference_scores_100_percent_and_the_template_0_in_the_uid_mode(autograder):
    ref = _grade(autograder, _source(EKF.module_path.read_text()))
    assert ref["score"] == ref["max_score"] > 0, ref["output"]
    assert ref["extra_data"]["sandbox"] == "uid" and ref["extra_data"]["secure"] is True
    template = _grade(autograder, _source(_template(autograder)))
    assert template["score"] == 0 and template["extra_data"]["sandbox"] == "uid"


def _template(autograder) -> str:
    root, _ = autograder
    return (root / "source" / "assignments" / "ekf" / "ekf.py").read_text()


@pytest.mark.slow  # nine gradings of the whole ekf suite through run_autograder (about a minute)
def test_no_attack_scores_more_than_the_template_in_the_uid_mode(autograder, tmp_path):
    root, _ = autograder
    bob = tmp_path / "bob" / "ekf.py"
    bob.parent.mkdir()
    bob.write_bytes(EKF.module_path.read_bytes())
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    attacks = every_attack(os.getpid(), root / "results" / "results.json", bob, server.getsockname()[1])
    scores = {}
    try:
        for name, attack in attacks.items():
            data = _grade(autograder, _source(_template(autograder) + "\n\n# ---- the attack\n" + attack))
            assert data["extra_data"]["sandbox"] == "uid", data["output"]
            scores[name] = data["score"]
    finally:
        server.close()
    # not a regular file: a link to the reference, a pipe
    scores["symlink_to_the_reference"] = _grade(
        autograder, lambda s: (s / "ekf.py").symlink_to(EKF.module_path)
    )["score"]
    scores["fifo"] = _grade(autograder, lambda s: os.mkfifo(s / "ekf.py"))["score"]
    print("scores in the uid mode:", scores)
    assert scores == dict.fromkeys(scores, 0.0), scores


def test_run_autograder_writes_results_even_when_grading_fails(autograder):
    root, env = autograder
    broken = {**env, "LAB_AUTOGRADER_PYTHON": str(root / "no-such-python")}
    (root / "submission").mkdir(exist_ok=True)
    run = root / "source" / "run_autograder"
    r = subprocess.run([str(run)], env=broken, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0
    data = json.loads((root / "results" / "results.json").read_text())
    assert data["score"] == 0 and data["extra_data"]["grading_failed"] is True
    assert "could not grade this submission" in data["output"]


def test_setup_fails_the_image_build_when_no_isolation_mode_works(autograder):
    root, env = autograder
    only_bwrap = {**env, "LAB_GRADE_SANDBOX": "bwrap"}  # and bubblewrap is hidden: no mode is left
    setup = _docker_like(["bash", str(root / "source" / "setup.sh")])
    r = subprocess.run(setup, env=only_bwrap, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1
    assert "BAD no sandbox" in r.stdout and "refusing to build" in r.stderr
