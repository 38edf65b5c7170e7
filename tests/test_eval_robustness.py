"""The robustness curve (``lab eval identify|search --error-scale 1,2,3``, lab/eval/robustness.py): the
scales parse or fail naming the bad value; each scale is a job with the profile's errors times it; the
report tables success against scale with Wilson intervals (hand-derived) and draws the figure."""

import math

import pytest

from lab.cli import main
from lab.cli.parser import build_parser
from lab.errors import ConfigError
from lab.eval.cli import identify_sweep, search_sweep
from lab.eval.robustness import parse_error_scales, robustness_points
from lab.eval.search import SEARCH, SearchSweep
from lab.eval.sweep import IDENTIFY, IdentifySweep, identify_job, write_report
from lab.sim.sensing import PROFILES


def test_error_scales_parse_from_the_flag_and_from_a_sweep_file():
    assert parse_error_scales("1,2,3") == (1.0, 2.0, 3.0)
    assert parse_error_scales(" 0.5, 1.5 ,") == (0.5, 1.5)
    assert parse_error_scales([1, 2.5]) == (1.0, 2.5)


@pytest.mark.parametrize(
    ("value", "names"),
    [
        ("1,x,3", "'x' is not a number"),
        ("0", "'0' is out of range"),
        ("-1", "'-1' is out of range"),
        ("nan", "'nan' is out of range"),
        ("inf", "'inf' is out of range"),
        ("25", "'25' is out of range"),
        ("1,2,1", "'1' is given twice"),
        ("", "is empty"),
        ([True], "True is not a number"),
    ],
)
def test_a_bad_error_scale_is_one_error_naming_it_and_what_is_allowed(value, names):
    with pytest.raises(ConfigError, match="--error-scale") as e:
        parse_error_scales(value)
    assert names in str(e.value) and "comma-separated numbers in (0, 20], e.g. 1,2,3" in str(e.value)


def test_the_cli_refuses_a_bad_scale_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "o"
    for sweep in ("search", "identify"):
        assert main(["eval", sweep, "--seeds", "0", "--error-scale", "1,two", "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--error-scale: 'two' is not a number" in err[0], err
    assert not out.exists()


def test_each_scale_is_a_job_with_its_own_key():
    ap = build_parser()
    argv = [
        "eval",
        "identify",
        "--seeds",
        "0",
        "--models",
        "1",
        "--planners",
        "lut",
        "--error-scale",
        "1,2,3",
    ]
    sw = identify_sweep(ap.parse_args([*argv, "--out", "o"]))
    assert sw.error_scale == (1.0, 2.0, 3.0)
    jobs = sw.jobs()
    assert [j.kwargs["error_scale"] for j in jobs] == [1.0, 2.0, 3.0]
    assert [j.key for j in jobs] == ["lut_evasive_realistic_m1_s0", "lut_evasive_realistic_m1_s0_x2",
                                     "lut_evasive_realistic_m1_s0_x3"]  # fmt: skip
    argv = [
        "eval",
        "search",
        "--seeds",
        "0",
        "--objects",
        "book",
        "--surfaces",
        "floor",
        "--strategies",
        "paper",
    ]
    ss = search_sweep(ap.parse_args([*argv, "--obstacles", "no", "--error-scale", "1,2.5", "--out", "o"]))
    keys = [j.key for j in ss.jobs()]
    assert keys == [
        "paper_free_realistic_landmarks_book_floor_s0",
        "paper_free_realistic_landmarks_book_floor_s0_x2.5",
    ]
    # the default: one scale, the keys as they always were
    assert IdentifySweep(seeds=(0,)).error_scale == SearchSweep(seeds=(0,)).error_scale == (1.0,)
    with pytest.raises(ConfigError, match="--error-scale: 0 is out of range"):
        SearchSweep(seeds=(0,), error_scale=(0,)).check()


def test_identify_sweeps_localization_keeping_the_default_jobs_names(monkeypatch):
    import lab.runs.identify

    ap = build_parser()
    argv = ["eval", "identify", "--seeds", "0", "--models", "1", "--planners", "lut", "--out", "o"]
    sw = identify_sweep(ap.parse_args(argv))
    assert sw.localization == ("odometry",)  # `lab identify`'s own default
    assert [j.key for j in sw.jobs()] == ["lut_evasive_realistic_m1_s0"]  # the names --resume knows
    sw = identify_sweep(ap.parse_args([*argv, "--localization", "odometry,landmarks"]))
    jobs = sw.jobs()
    assert [j.key for j in jobs] == ["lut_evasive_realistic_m1_s0", "lut_evasive_realistic_landmarks_m1_s0"]
    seen = []
    monkeypatch.setattr(lab.runs.identify, "run_identify", lambda **kw: seen.append(kw["localization"]) or {})
    for j in jobs:
        j.fn(**j.kwargs)
    assert seen == ["odometry", "landmarks"]  # what reaches the episode
    with pytest.raises(ConfigError, match="unknown localization 'gps'; allowed: odometry, landmarks"):
        identify_sweep(ap.parse_args([*argv, "--localization", "gps"]))


def test_a_job_runs_with_the_profiles_errors_times_its_scale(monkeypatch):
    import lab.runs.identify

    seen = {}
    monkeypatch.setattr(lab.runs.identify, "run_identify", lambda **kw: seen.update(kw) or {})
    identify_job(error_scale=2.0, true_model=1, seed=0, sensing="realistic")
    p = seen["sensing"]
    assert p == PROFILES["realistic"].scaled(2.0) and p.name == "realistic x2"
    assert p.room.survey_m == pytest.approx(2 * 0.015) and p.camera.noise_grey_at_mid == pytest.approx(4.0)
    identify_job(true_model=1, seed=0, sensing="ideal")
    assert seen["sensing"] is PROFILES["ideal"]


def _wilson(k, n, z=1.959963984540054):
    """The Wilson score interval, written out from its definition (Wilson 1927)."""
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return c - h, c + h


def _rows(scale, k, n, **extra):
    return [
        {"key": f"j{scale}_{i}", "seed": i, "success": i < k, "error": "", "error_scale": scale, **extra}
        for i in range(n)
    ]


def test_the_report_tables_success_against_scale_and_draws_the_figure(tmp_path):
    cond = {"planner": "lut", "mover": "evasive", "sensing": "realistic", "localization": "odometry"}
    cond.update(actions=3, max_actions=8)
    cond["sim_time_s"] = 20.0
    rows = _rows(1.0, 9, 10, **cond) + _rows(2.0, 7, 10, **cond) + _rows(3.0, 2, 8, **cond)
    rows.append({**_rows(3.0, 0, 1, **cond)[0], "key": "broken", "error": "RuntimeError: x"})  # not counted
    pts = robustness_points(rows)
    assert [(p.sensing, p.scale, p.successes, p.runs) for p in pts] == [
        ("realistic", 1.0, 9, 10),
        ("realistic", 2.0, 7, 10),
        ("realistic", 3.0, 2, 8),
    ]
    for p in pts:
        assert (p.low, p.high) == pytest.approx(_wilson(p.successes, p.runs), abs=1e-12)
    write_report(tmp_path, rows, IDENTIFY)
    text = (tmp_path / "report.md").read_text()
    assert "## Robustness: success against error scale" in text
    lo, hi = _wilson(7, 10)
    assert f"| realistic | 2 | 7/10 | 70.0 % | [{100 * lo:.1f}, {100 * hi:.1f}] % |" in text
    assert "| lut | evasive | realistic | odometry | 3.0 | 2/8 |" in text  # the conditions split by scale too
    assert (tmp_path / "robustness.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # one curve per profile: another profile's rows are counted apart
    rows += [dict(r, sensing="sensors", key="s" + r["key"]) for r in _rows(1.0, 3, 3, **cond)]
    assert [(p.sensing, p.scale, p.successes) for p in robustness_points(rows)][:2] == [
        ("realistic", 1.0, 9),
        ("realistic", 2.0, 7),
    ]
    points = [(p.sensing, p.scale, p.successes, p.runs) for p in robustness_points(rows)]
    assert ("sensors", 1.0, 3, 3) in points
    write_report(tmp_path, rows, IDENTIFY)
    assert "| sensors | 1 | 3/3 | 100.0 % |" in (tmp_path / "report.md").read_text()


def test_one_scale_writes_the_report_as_before(tmp_path):
    rows = [dict(r, error_scale=None) for r in _rows(1.0, 1, 2, strategy="paper", obstacles=False)]
    for r in rows:
        r.update(sensing="ideal", localization="landmarks", found=True, shortest_path_m=None)
        r.update(path_length_m=1.0, sim_time_s=1.0, collisions=0)
    write_report(tmp_path, rows, SEARCH)
    text = (tmp_path / "report.md").read_text()
    assert "Robustness" not in text and not (tmp_path / "robustness.png").exists()
    assert "| paper | False | ideal | landmarks | 1/2 |" in text
