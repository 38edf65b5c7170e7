"""The command-line contract's JSON Schemas (lab/schemas/): valid schemas that keep design.md's fields,
reject outputs that break them, accept the evaluation summary that benchmarks/eval_identify.py writes,
and a validator command with one-line errors. The real outputs of `lab identify`, `lab search` and
`lab grade` are validated where those commands are tested (test_identify_cli, test_search_cli,
test_search_agent, test_grade_cli, test_grade_assignments)."""

import copy
import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from lab.contract import KINDS, ContractError, problems, schema, validate
from lab.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent

# design.md's "Command-line contract": the fields every output keeps
DESIGN_FIELDS = {
    "identify": "true_model identified_model success actions sim_time_s wall_time_s final_posterior history "
    "pose_error planner seed",
    "search": "object found true_pose estimated_pose position_error_m orientation_error_deg path_length_m "
    "global_searches local_searches collisions sim_time_s wall_time_s seed success reason",
    "grade": "tests score",
}
# also in design.md, not yet written by the commands: defined in the schemas, not required
LATER = "reason sensing odometry_error_m localization_error_m"


def identify_output(model=1, seed=0, planner="lut", success=True, actions=2):
    return {
        "true_model": model,
        "identified_model": model if success else None,
        "success": success,
        "actions": actions,
        "sim_time_s": 31.5,
        "wall_time_s": 12.0,
        "final_posterior": [0.01, 0.97, 0.01, 0.01] if success else [0.25] * 4,
        "history": [
            {"t": 0.0, "posterior": [0.25] * 4, "ptu_state": "scanning", "action": None},
            {"t": 0.5, "posterior": [0.1, 0.7, 0.1, 0.1], "ptu_state": "tracking", "action": 0},
        ],
        "pose_error": {"translation_m": 0.02, "rotation_deg": 3.0},
        "planner": planner,
        "seed": seed,
        "mover": "static",  # more fields are allowed
    }


def search_output():
    return {
        "object": "book",
        "found": False,
        "true_pose": {"xyz": [1.0, 2.0, 0.75], "yaw_deg": 30.0},
        "estimated_pose": None,
        "position_error_m": None,
        "orientation_error_deg": None,
        "path_length_m": 4.2,
        "global_searches": 2,
        "local_searches": 3,
        "collisions": 0,
        "sim_time_s": 100.0,
        "wall_time_s": 50.0,
        "seed": 1,
        "success": False,
        "reason": "time budget spent",
    }


def grade_output():
    test = {"name": "t", "score": 1.0, "max_score": 2.0, "status": "failed", "visibility": "visible"}
    return {"score": 1.0, "execution_time": 3.0, "tests": [test]}


GOOD = {"identify": identify_output, "search": search_output, "grade": grade_output}


@pytest.mark.parametrize("kind", KINDS)
def test_each_schema_is_a_valid_draft_2020_12_schema(kind):
    Draft202012Validator.check_schema(schema(kind))


@pytest.mark.parametrize("kind", sorted(DESIGN_FIELDS))
def test_the_schemas_require_design_md_fields_and_define_the_later_ones(kind):
    s = schema(kind)
    assert set(DESIGN_FIELDS[kind].split()) <= set(s["required"])
    if kind != "grade":
        assert set(LATER.split()) <= set(s["properties"])


@pytest.mark.parametrize("kind", sorted(GOOD))
def test_a_conforming_output_passes_and_each_missing_field_is_named(kind):
    good = GOOD[kind]()
    assert problems(kind, good) == []
    validate(kind, good)
    for field in DESIGN_FIELDS[kind].split():
        bad = {k: v for k, v in good.items() if k != field}
        assert problems(kind, bad) == [f"(top): '{field}' is a required property"]


@pytest.mark.parametrize(
    "kind, edit, where",
    [
        ("identify", lambda d: d.update(true_model=True), "true_model"),  # a bool is not an integer
        ("identify", lambda d: d.update(actions=1.5), "actions"),
        ("identify", lambda d: d.update(planner="oracle"), "planner"),
        ("identify", lambda d: d["history"][1].update(ptu_state="dancing"), "history[1].ptu_state"),
        ("identify", lambda d: d["history"][0].pop("posterior"), "history[0]"),
        ("identify", lambda d: d["final_posterior"].__setitem__(0, 1.5), "final_posterior[0]"),
        ("identify", lambda d: d["pose_error"].pop("rotation_deg"), "pose_error"),
        ("search", lambda d: d.update(collisions=-1), "collisions"),
        ("search", lambda d: d.update(found="yes"), "found"),
        ("search", lambda d: d.update(estimated_pose="here"), "estimated_pose"),
        ("grade", lambda d: d["tests"][0].update(visibility="secret"), "tests[0].visibility"),
        ("grade", lambda d: d["tests"][0].pop("max_score"), "tests[0]"),
    ],
)
def test_a_broken_field_is_named_with_its_path(kind, edit, where):
    d = copy.deepcopy(GOOD[kind]())
    edit(d)
    found = problems(kind, d)
    assert len(found) == 1 and found[0].startswith(f"{where}: "), found
    with pytest.raises(ContractError, match=f"{kind} output breaks the contract: .*{re.escape(where)}"):
        validate(kind, d)


def test_unknown_contract_is_one_clear_error():
    with pytest.raises(ConfigError, match="unknown contract 'demo'; contracts: identify, search, eval"):
        schema("demo")


def _eval_identify():
    spec = importlib.util.spec_from_file_location("eval_identify", ROOT / "benchmarks" / "eval_identify.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_evaluation_summary_keeps_the_eval_schema(tmp_path):
    ev = _eval_identify()
    for planner in ("lut", "random"):
        for m in (0, 1):
            for s in (0, 1):
                res = identify_output(m, s, planner, success=(planner == "lut" or s == 0), actions=1 + s)
                assert problems("identify", res) == []
                p = ev.episode_path(tmp_path, planner, m, s)
                p.parent.mkdir(parents=True, exist_ok=True)
                p.write_text(json.dumps(res))
    summary = json.loads(json.dumps(ev.summarise(tmp_path, ["lut", "random"], [0, 1], [0, 1], 8)))
    assert problems("eval", summary) == []
    assert summary["planners"]["lut"]["success"] == 4 and summary["planners"]["random"]["success"] == 2
    assert summary["lut_vs_random"]["paired_episodes"] == 4
    summary["planners"]["lut"]["actions"].pop("median")  # a distribution of n >= 1 has its quartiles
    assert problems("eval", summary) == ["planners.lut.actions: 'median' is a required property"]


def _contract_cmd(*args):
    cmd = [sys.executable, "-m", "lab.contract", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True)


def test_the_validator_command(tmp_path):
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text(json.dumps(search_output()))
    bad.write_text(json.dumps({**search_output(), "seed": "one"}))
    r = _contract_cmd("search", good)
    assert r.returncode == 0 and r.stdout.strip() == "contract ok"
    r = _contract_cmd("search", bad)
    assert r.returncode == 1 and r.stdout.strip() == f"{bad}: seed: 'one' is not of type 'integer'"
    # bad input: one line naming what is wrong, no traceback
    (tmp_path / "torn.json").write_text('{"object": ')
    for args, says in (
        (("search", tmp_path / "torn.json"), "cannot read it as JSON"),
        (("search", tmp_path / "missing.json"), "No such file"),
        (("demo", good), "usage: python -m lab.contract {identify,search,eval,grade} FILE.json"),
    ):
        r = _contract_cmd(*args)
        assert r.returncode == 2 and says in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
