"""`lab search`: the object list, one-line errors, and a run through the Navigator that keeps the contract."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

CHECKER = Path(__file__).resolve().parents[2] / "shared" / "tools" / "check_contract.py"


def _lab(*args, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "lab", *args], capture_output=True, text=True, timeout=timeout
    )


def test_list_objects_and_bad_input():
    r = _lab("search", "--list-objects")
    assert r.returncode == 0 and r.stdout.split() == ["cereal_box", "book", "toy_block", "glossy_cup"]
    r = _lab("search", "--object", "sofa")
    assert r.returncode == 2 and "unknown object 'sofa'; searchable objects: cereal_box" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_search_run_finds_the_toy_block_and_keeps_the_contract(tmp_path):
    r = _lab(
        "search",
        "--object",
        "toy_block",
        "--seed",
        "1",
        "--max-time",
        "240",
        "--json",
        str(tmp_path / "s.json"),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((tmp_path / "s.json").read_text())
    assert res["found"] and res["position_error_m"] <= 0.05 and res["orientation_error_deg"] <= 10
    assert res["collisions"] == 0
    if CHECKER.is_file():
        c = subprocess.run(
            [sys.executable, str(CHECKER), "search", str(tmp_path / "s.json")], capture_output=True, text=True
        )
        assert c.returncode == 0, c.stdout
