"""The grader enforces an assignment's rules, keeps records a student cannot erase, and starts the same
however it is launched (issue 48): one submission per way a student tried, each written against the
released template, each scoring no more than the untouched template (0).
"""

import importlib.util
import json
import os
import subprocess
import sys

import pytest
from grade_modes import *  # noqa: F403  (the fixtures grading_mode and any_mode)

from lab.errors import ConfigError
from lab.grading import get_assignment, grade_submission
from lab.grading.records import CLOSED, WRITTEN
from lab.grading.release import release
from lab.grading.rules import importable_from_grader, oracle_folders, oracles
from lab.grading.sandbox import decode, encode

SEARCH = get_assignment("search")
STEREO = get_assignment("stereo")
EKF = get_assignment("ekf")
ASTAR_TESTS = ("astar_valid_path", "astar_optimal", "astar_no_path", "astar_large_map")


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """The released (solutions stripped) modules, as students receive them."""
    out = tmp_path_factory.mktemp("release")
    release([SEARCH, STEREO, EKF], out)
    return {a.name: (out / a.name / a.module).read_text() for a in (SEARCH, STEREO, EKF)}


def _submission(tmp_path, source, module, name="student"):
    d = tmp_path / name
    d.mkdir(parents=True)
    (d / module).write_text(source)
    return d


# ---- 1. the assignment's rules: networkx, the graded tests' oracle, however the student tries
NETWORKX = """

# ---- the attack: A* by networkx, the graded tests' own oracle, had however it can be
_sys = np.__spec__.loader.__class__.get_data.__globals__["sys"]  # sys without an import statement
_TRIES = []


def _networkx():
    importlib, os, site = (_sys.modules[n] for n in ("importlib", "os", "site"))
    sites = [p for p in _sys.path if p.endswith("-packages")] + site.getsitepackages()

    def statement():
        import networkx

        return networkx

    def by_path():  # the package's files, loaded by hand
        init = os.path.join(sites[0], "networkx", "__init__.py")
        spec = importlib.util.spec_from_file_location("nx2", init, submodule_search_locations=[])
        m = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(m)
        return m

    def spoofed():  # its source run under its own file name, as if it were the package
        init = os.path.join(sites[0], "networkx", "__init__.py")
        g = {"__name__": "networkx", "__path__": [os.path.dirname(init)], "__file__": init}
        exec(compile(open(init).read(), init, "exec"), g)
        return type("M", (), g)

    def no_finders():  # the import rules' finder taken off sys.meta_path
        _sys.meta_path[:] = [f for f in _sys.meta_path if type(f).__name__ == "PathFinder"]
        return importlib.import_module("networkx")

    def python_import():  # importlib's own __import__ in place of the builtin one
        _sys.modules["builtins"].__import__ = importlib.__import__
        return importlib.__import__("networkx")

    ways = [
        ("statement", statement),
        ("__import__", lambda: __import__("networkx")),
        ("import_module", lambda: importlib.import_module("networkx")),
        ("sys.modules", lambda: _sys.modules.get("networkx")),
        ("by_path", by_path),
        ("spoofed", spoofed),
        ("no_finders", no_finders),
        ("python_import", python_import),
        ("statement_again", statement),
    ]
    for name, way in ways:
        _sys.modules.pop("networkx", None)
        try:
            m = way()
        except BaseException as e:
            _TRIES.append(f"{name}: {type(e).__name__}")
            continue
        if m is None:
            _TRIES.append(f"{name}: nothing")
        elif hasattr(m, "dijkstra_path"):
            _TRIES.append(f"{name}: GOT IT")
            return m
        else:
            _TRIES.append(f"{name}: an empty module")


def astar(cost, start, goal):
    nx = _networkx()
    print("; ".join(_TRIES))
    cost = np.asarray(cost, dtype=float)
    n, m = cost.shape
    G = nx.DiGraph()
    for i in range(n):
        for j in range(m):
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    u, v = i + di, j + dj
                    if not ((di or dj) and 0 <= u < n and 0 <= v < m):
                        continue
                    if not (np.isfinite(cost[i, j]) and np.isfinite(cost[u, v])):
                        continue
                    if di and dj and not (np.isfinite(cost[i + di, j]) and np.isfinite(cost[i, j + dj])):
                        continue
                    G.add_edge((i, j), (u, v), weight=math.hypot(di, dj) * cost[u, v])
    try:
        path = nx.dijkstra_path(G, tuple(start), tuple(goal))
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return np.zeros((0, 2), dtype=int), math.inf
    return np.array(path, dtype=int), float(nx.path_weight(G, path, "weight"))
"""


class _Module:
    """A submission imported here, in the test's own process (where networkx is importable), to show
    that the attack is real: the graded tests pass with it."""

    def __init__(self, path):
        spec = importlib.util.spec_from_file_location("networkx_attack", path)
        self.module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(self.module)

    def __getattr__(self, name):
        f = getattr(self.module, name)
        return lambda *args: decode(encode(f(*args)))  # values as the grader gets them (tuples as lists)


def test_an_astar_that_calls_networkx_scores_no_more_than_the_template(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template["search"] + NETWORKX, "search.py")
    graded = {t.id: t for t in SEARCH.load_suite().tests}
    for test_id in ASTAR_TESTS:  # with networkx at hand, its A* passes the graded tests
        graded[test_id].func(_Module(sub / "search.py"))
    report = grade_submission(SEARCH, sub)
    assert report.score == 0, report.summary()
    out = report.by_id()["astar_valid_path"].output
    assert "statement: ImportError" in out and "statement_again: " in out  # every way tried
    assert "GOT IT" not in out, out
    for way in ("by_path", "spoofed"):  # the package's files: refused, or not there at all
        assert f"{way}: PermissionError" in out or f"{way}: FileNotFoundError" in out, out
    rule = "import networkx: assignment 'search' allows only __future__, bisect"
    assert any(n.startswith(rule) for n in report.refused), report.refused


def test_a_module_the_rules_do_not_list_is_refused_with_the_rule(tmp_path, template, any_mode):
    src = template["stereo"].replace("import numpy as np\n", "import os\nimport numpy as np\n", 1)
    report = grade_submission(STEREO, _submission(tmp_path, src, "stereo.py"))
    assert report.score == 0
    said = "importing 'os' is not allowed in a submission: assignment 'stereo' allows only __future__, cmath"
    assert report.error and said in report.error, report.error
    assert all(said in r.output for r in report.tests)


def test_the_oracles_are_the_graded_tests_imports_the_student_may_not_use():
    assert oracles(SEARCH) == ("lab", "networkx")
    assert oracles(EKF) == ("lab", "scipy") and oracles(STEREO) == ("cv2", "lab")
    import networkx

    assert oracle_folders(["networkx"]) == (os.path.realpath(os.path.dirname(networkx.__file__)),)


@pytest.mark.parametrize("value", ['"numpy"', '["numpy", 3]', '["numpy", "lab"]', '["os.path"]'])
def test_an_imports_field_that_is_not_a_list_of_module_names_is_refused(tmp_path, value):
    folder = tmp_path / "toy"
    folder.mkdir()
    (folder / "assignment.toml").write_text(
        f'title = "toy"\nmodule = "toy.py"\nrelease = ["toy.py"]\nimports = {value}\n'
    )
    (folder / "toy.py").write_text("")
    (folder / "hidden_tests.py").write_text("")
    with pytest.raises(ConfigError, match="'imports'"):
        get_assignment("toy", tmp_path)


# ---- 2. records a student cannot erase, and no false ones
def test_the_template_and_the_reference_are_graded_without_a_note(tmp_path, template, grading_mode):
    """Every test of the template raises NotImplementedError: its traceback is no refused attempt."""
    for a, sub in ((EKF, _submission(tmp_path, template["ekf"], "ekf.py")), (SEARCH, SEARCH.module_path)):
        report = grade_submission(a, sub)
        assert report.refused == [], (a.name, report.refused)
        assert not any("refused" in r.output for r in report.tests)


ERASE = """

# ---- the attack: a refused attempt, then every way to erase its record
_sys = np.__spec__.loader.__class__.get_data.__globals__["sys"]
_os = _sys.modules["os"]


def _attempt(path):
    try:
        open(path).close()
    except OSError:
        pass


def _erase():
    keep = {int(a) for a in _sys.argv[1:3]}  # the request and answer pipes: the calls go on
    main = _sys.modules["__main__"]
    for name, value in list(vars(main).items()):
        if isinstance(value, (list, set, dict)) and not name.startswith("__"):
            value.clear()
        if callable(value) and ("note" in name or "watch" in name or "record" in name):
            setattr(main, name, lambda *a, **k: None)
    for fd in range(3, 64):
        if fd not in keep:
            try:
                _os.close(fd)
            except OSError:
                pass


def triangulate(uv, disparity, f, cx, cy, baseline):
    _attempt("/etc/shadow")  # refused and noted...
    _erase()  # ... then the record erased
    _attempt("/etc/passwd")
    raise NotImplementedError
"""

GARBLE = """

_sys = np.__spec__.loader.__class__.get_data.__globals__["sys"]


def project(points_C, f, cx, cy):
    keep = {int(a) for a in _sys.argv[1:3]}
    for fd in range(3, 64):
        if fd not in keep:
            try:
                _sys.modules["posix"].write(fd, b"Nall is well\\nM7\\n" + b"x" * 2000)
            except OSError:
                pass
    raise NotImplementedError
"""


def test_a_refused_attempt_stays_recorded_however_the_record_is_erased(tmp_path, template, grading_mode):
    sub = _submission(tmp_path, template["stereo"] + ERASE + GARBLE, "stereo.py")
    report = grade_submission(STEREO, sub)
    assert report.score == 0, report.summary()
    erased = report.by_id()["triangulate_matches_opencv"]
    assert any(n.startswith("open /etc/shadow: outside the submission") for n in erased.refused), erased
    assert CLOSED in erased.refused  # the grader saw the record closed, from its side
    assert "The grader's sandbox refused" in erased.output and "/etc/shadow" in erased.output
    garbled = report.by_id()["project_matches_opencv"]
    assert WRITTEN in garbled.refused and CLOSED in garbled.refused, garbled.refused


# ---- 3. the grader starts the same however it is launched
def _shadowing_folder(tmp_path, template):
    """A submission folder with its own numpy.py, which leaves a mark when it is imported."""
    sub = _submission(tmp_path, template["ekf"], "ekf.py")
    mark = tmp_path / "numpy_was_imported"
    (sub / "numpy.py").write_text(f"open({str(mark)!r}, 'w').close()\nraise SystemExit(3)\n")
    return sub, mark


def test_python_dash_m_lab_inside_a_submission_folder_does_not_import_its_numpy(tmp_path, template, any_mode):
    sub, mark = _shadowing_folder(tmp_path, template)
    out = tmp_path / "results.json"
    r = subprocess.run(
        [sys.executable, "-m", "lab", "grade", "ekf", ".", "--json", str(out), "--quiet"],
        cwd=sub,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert not mark.exists()
    data = json.loads(out.read_text())
    assert data["score"] == 0 and data["extra_data"]["secure"] is True


def test_a_submission_folder_the_grader_could_import_is_refused(tmp_path, template, any_mode):
    sub = _submission(tmp_path, template["ekf"], "ekf.py")
    (sub / "turtle.py").write_text("")  # would shadow the standard library's, were it imported
    out = tmp_path / "results.json"
    env = {**os.environ, "PYTHONPATH": "."}
    r = subprocess.run(
        [sys.executable, "-m", "lab", "grade", "ekf", ".", "--json", str(out), "--quiet"],
        cwd=sub,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert data["score"] == 0
    said = f"the submission folder {sub.resolve()} is on the grader's import path (sys.path); its turtle"
    assert said in data["output"], data["output"]


def test_a_folder_is_importable_when_it_or_a_parent_named_like_a_module_is_on_the_path(tmp_path, monkeypatch):
    inside = tmp_path / "numpy" / "alice"
    inside.mkdir(parents=True)
    elsewhere = tmp_path / "class" / "bob"
    elsewhere.mkdir(parents=True)
    monkeypatch.setattr(sys, "path", [str(tmp_path), *sys.path])
    assert "is inside" in importable_from_grader(inside) and "numpy" in importable_from_grader(inside)
    assert importable_from_grader(elsewhere) is None  # "class" is no module the grader has
    assert "is on the grader's import path" in importable_from_grader(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p != str(tmp_path)])
    assert importable_from_grader(inside) is None
    monkeypatch.setattr(sys, "path", ["", *sys.path])  # '' is the working directory
    monkeypatch.chdir(elsewhere)
    assert "is on the grader's import path" in importable_from_grader(elsewhere)
