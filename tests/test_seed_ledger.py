"""The ledger of spent report seeds (issue 52): it parses and ships in the package; every default of the
evaluations avoids every seed in it; a spent seed is refused with the override named, and reported on
only when asked, marked; a malformed ledger is one clear error; `lab eval spend` appends to it."""

import importlib.util
import sys
import tomllib
from importlib import resources
from pathlib import Path

import pytest

from lab.cli import main
from lab.cli.parser import build_parser
from lab.errors import ConfigError
from lab.evaluation import (
    REPORT_SEEDS_START,
    SpentSeeds,
    check_report_seeds,
    fresh_report_seeds,
    is_spent,
    ledger_path,
    load_ledger,
    spent_among,
    spent_seeds,
)

ROOT = Path(__file__).resolve().parents[1]


def _benchmark(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # a module's dataclasses look themselves up there
    spec.loader.exec_module(mod)
    return mod


def test_the_ledger_parses_and_ships_in_the_package():
    entries = load_ledger()
    assert entries and all(isinstance(e, SpentSeeds) for e in entries)
    assert all(e.first >= REPORT_SEEDS_START and e.last >= e.first and e.decided and e.runs for e in entries)
    # importlib.resources finds it, and the wheel's package data includes it
    res = resources.files("lab").joinpath("data", "spent_seeds.toml")
    assert res.is_file() and Path(str(res)) == ledger_path()
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "data/*.toml" in data["lab"]


@pytest.mark.parametrize(
    "seeds",
    [
        range(100000, 100025),  # identification's acceptance and the former defaults
        range(100000, 100020),  # the localization drives
        range(100300, 100305),  # the localizer's recount rule
        [101000, 101100, 100400, 100403],  # the heading floor, the revisit rule, a navigator fix
        range(101000, 101005),  # the evaluation's 600 s budget
        range(101200, 101205),  # reported on in stop 44
    ],
)
def test_the_seeds_issue_52_names_are_spent(seeds):
    assert all(is_spent(s) for s in seeds)


def _eval_defaults():
    from lab.eval.cli import identify_sweep, search_sweep

    ap = build_parser()
    return {
        "lab eval identify": identify_sweep(ap.parse_args(["eval", "identify", "--out", "o"])).seeds,
        "lab eval search": search_sweep(ap.parse_args(["eval", "search", "--out", "o"])).seeds,
        "eval_identify.py": _benchmark("eval_identify").build_parser().parse_args([]).seeds,
        "eval_search.py": _seeds(_benchmark("eval_search").build_parser().parse_args(["run", "--out", "o"])),
        "bench_localization.py": _benchmark("bench_localization").build_parser().parse_args([]).seeds,
        "bench_nees.py": _benchmark("bench_nees").build_parser().parse_args([]).seeds,
    }


def _seeds(args):
    from lab.evaluation import parse_seeds

    return parse_seeds(args.seeds)


def test_the_evaluation_defaults_avoid_every_seed_in_the_ledger():
    spent = spent_seeds()
    defaults = _eval_defaults()
    assert len(defaults["lab eval identify"]) == 25 and len(defaults["lab eval search"]) == 2
    for name, seeds in defaults.items():
        assert seeds and all(s >= REPORT_SEEDS_START for s in seeds), name
        assert not spent & set(seeds), f"{name} defaults to spent seeds {sorted(spent & set(seeds))}"
        check_report_seeds(seeds)  # not refused
    for n in (1, 2, 25, 250):
        fresh = fresh_report_seeds(n)
        assert len(fresh) == n and not spent & set(fresh) and min(fresh) > max(spent)


def _entry(first, last):
    return SpentSeeds(first, last, "a test", ("search",))


def test_fresh_seeds_start_on_the_next_block_above_every_spent_seed():
    assert fresh_report_seeds(3, []) == [REPORT_SEEDS_START, REPORT_SEEDS_START + 1, REPORT_SEEDS_START + 2]
    assert fresh_report_seeds(2, [_entry(100000, 100004), _entry(101200, 101204)]) == [101300, 101301]
    assert fresh_report_seeds(1, [_entry(101299, 101299)]) == [101300]
    assert fresh_report_seeds(1, [_entry(101300, 101300)]) == [101400]
    # a gap between entries is not used: it may hold seeds looked at and never recorded
    assert fresh_report_seeds(1, [_entry(100000, 100000), _entry(100900, 100904)]) == [101000]


def test_a_spent_seed_is_refused_in_one_line_naming_it_and_the_override(tmp_path, capsys):
    out = tmp_path / "o"
    for argv in (["eval", "search", "--seeds", "3,100403"], ["eval", "identify", "--seeds", "101000-101004"]):
        assert main([*argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        seed = "100403" if "search" in argv else "101000"
        assert f"seed {seed} is spent: it decided" in err[0] and "--allow-spent-seeds" in err[0], err[0]
        assert not out.exists()
    with pytest.raises(ConfigError, match=r"seed 100300 is spent: it decided the localizer's recount rule"):
        check_report_seeds([100300])
    assert check_report_seeds(range(1000)) == {}  # tuning seeds are never refused
    assert set(check_report_seeds([5, 100000, 100001], allow_spent=True)) == {100000, 100001}


def test_the_benchmarks_refuse_spent_seeds_too(capsys):
    assert _benchmark("eval_identify").main(["--seeds", "100000-100024", "--out", "unused"]) == 2
    err = capsys.readouterr().err
    assert "seed 100000 is spent" in err and "--allow-spent-seeds" in err
    assert _benchmark("eval_search").main(["run", "--seeds", "101200,101201", "--out", "unused"]) == 2
    assert "seed 101200 is spent" in capsys.readouterr().err
    # the localization drives' and the EKF consistency benchmark's former defaults, refused in one line
    for name, seeds in (("bench_localization", "100000-100019"), ("bench_nees", "100000-100007")):
        assert _benchmark(name).main(["--seeds", seeds]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert (
            len(err) == 1
            and f"{name}: error: seed 100000 is spent" in err[0]
            and "--allow-spent-seeds" in err[0]
        )


def test_allow_spent_seeds_runs_and_the_report_says_on_spent_seeds(tmp_path, monkeypatch, capsys):
    """The sweep itself is replaced: its jobs are recorded as not run, and the real report is written."""
    import lab.eval.executor
    import lab.eval.sweep
    from lab.eval.sweep import write_report

    class NoExecutor:
        name = "nothing"

        def close(self):
            pass

    def fake_run_sweep(out, jobs, ex, resume=False, echo=print, kind=None):
        rows = [
            {**{k: j.kwargs.get(k) for k in kind.params}, "key": j.key, "success": False, "error": "not run"}
            for j in jobs
        ]
        write_report(out, rows, kind)
        return rows

    monkeypatch.setattr(lab.eval.sweep, "run_sweep", fake_run_sweep)
    monkeypatch.setattr(lab.eval.executor, "make_executor", lambda *a: NoExecutor())
    out = tmp_path / "o"
    argv = ["eval", "search", "--seeds", "100000-100001", "--strategies", "paper", "--out", str(out)]
    assert main([*argv, "--allow-spent-seeds"]) == 1  # every job "failed": not run
    printed = capsys.readouterr().out
    assert "split: report (seeds 100000-100001, 2 seeds; ON SPENT SEEDS: 100000-100001)" in printed
    report = (out / "report.md").read_text()
    assert "**On spent seeds:** 2 of the 2 seeds (100000-100001) are in the ledger" in report

    fresh = tmp_path / "fresh"
    assert main(["eval", "search", "--strategies", "paper", "--out", str(fresh)]) == 1
    assert "ON SPENT SEEDS" not in capsys.readouterr().out
    assert "spent" not in (fresh / "report.md").read_text()


def test_the_identify_benchmark_marks_a_summary_on_spent_seeds(tmp_path, capsys):
    ev = _benchmark("eval_identify")
    argv = ["--out", str(tmp_path), "--seeds", "100000-100001", "--planners", "lut", "--report-only"]
    assert ev.main(argv) == 0  # reading results already there is never refused, only marked
    assert "ON SPENT SEEDS: 100000-100001" in capsys.readouterr().out
    assert ev.summarise(tmp_path, ["lut"], [0], [100000, 100001], 8)["on_spent_seeds"] == "100000-100001"
    assert ev.summarise(tmp_path, ["lut"], [0], [0, 1], 8)["on_spent_seeds"] is None


GOOD = '[[spent]]\nfirst = 100000\nlast = 100004\ndecided = "x"\nruns = ["search"]\n'


@pytest.mark.parametrize(
    "text, what",
    [
        ("[[spent]\nfirst = 1", "is not valid TOML"),
        (GOOD.replace('decided = "x"\n', ""), "entry 1 lacks decided"),
        (GOOD + "colour = 'red'\n", "entry 1 has unknown field(s) colour"),
        (GOOD.replace("first = 100000", "first = 3"), "entry 1: 3 is not a report seed"),
        (GOOD.replace("last = 100004", "last = 99999"), "the range 100000-99999 runs backwards"),
        (GOOD.replace('runs = ["search"]', 'runs = "search"'), "'runs' must be a list"),
        (GOOD.replace('decided = "x"', 'decided = " "'), "'decided' must say what the seeds decided"),
        (GOOD + 'date = "4 Dec"\n', "date must be YYYY-MM-DD"),
        (GOOD.replace("first = 100000", 'first = "100000"'), "first and last must be integers"),
        ("[seeds]\nfirst = 1\n", "unknown table(s) seeds"),
        ("spent = 3\n", "'spent' must be an array of tables"),
    ],
)
def test_a_malformed_ledger_is_one_clear_error_naming_the_file(tmp_path, text, what):
    p = tmp_path / "ledger.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_ledger(p)
    msg = str(e.value)
    assert str(p) in msg and what in msg and "\n" not in msg, msg


def test_a_missing_ledger_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"seed ledger .*nowhere.toml does not exist"):
        load_ledger(tmp_path / "nowhere.toml")


def test_lab_eval_spend_appends_atomically(tmp_path, capsys):
    p = tmp_path / "ledger.toml"
    p.write_text("# kept\n" + GOOD)
    argv = ["eval", "spend", "101300-101302,101305", "--why", 'judged "it"', "--runs", "search,identify",
            "--commit", "abc1234", "--ledger", str(p)]  # fmt: skip
    assert main(argv) == 0
    assert "101300-101302, 101305 spent" in capsys.readouterr().out
    entries = load_ledger(p)
    assert p.read_text().startswith("# kept\n") and len(entries) == 3
    new = entries[1]
    assert (new.first, new.last, new.decided, new.runs, new.commit) == (
        101300, 101302, 'judged "it"', ("search", "identify"), "abc1234"
    )  # fmt: skip
    assert new.date is not None and (entries[2].first, entries[2].last) == (101305, 101305)
    assert set(spent_among([101301, 101304, 101305], p)) == {101301, 101305}
    assert fresh_report_seeds(1, p) == [101400]
    assert sorted(x.name for x in tmp_path.iterdir()) == ["ledger.toml"]  # no temporary file left

    before = p.read_text()
    assert main(["eval", "spend", "7", "--why", "tuning", "--ledger", str(p)]) == 2
    assert "seed 7 is not a report seed" in capsys.readouterr().err
    assert main(["eval", "spend", "101500", "--why", " ", "--ledger", str(p)]) == 2
    assert p.read_text() == before  # a refused spending leaves the ledger as it was
