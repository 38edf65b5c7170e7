"""The `lab` command: help on every subcommand, outputs that say what they should, one-line errors."""

import json
import subprocess
import sys

import cv2
import pytest

from lab.cli import build_parser, main


def _run(*args):
    return subprocess.run([sys.executable, "-m", "lab", *args], capture_output=True, text=True, timeout=300)


def test_help_lists_and_explains_every_subcommand():
    r = _run("--help")
    assert r.returncode == 0
    sub = build_parser()._subparsers._group_actions[0].choices
    for name in sub:
        assert name in r.stdout
        h = _run(name, "--help")
        assert h.returncode == 0 and "usage: lab " + name in h.stdout


def test_render_writes_a_stereo_pair_and_disparity(tmp_path):
    assert (
        main(
            [
                "render",
                "--world",
                "box_database",
                "--model",
                "M3",
                "--at=-1.0,0,0",
                "--pan-tilt",
                "0,-12",
                "--size",
                "160x120",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    left, right, disp = (cv2.imread(str(tmp_path / f)) for f in ("left.png", "right.png", "disparity.png"))
    assert left.shape == right.shape == disp.shape == (120, 160, 3)
    assert (left != right).any()  # two viewpoints
    assert (disp.sum(axis=2) > 0).mean() > 0.3  # dense disparity found on a good part of the image


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["render", "--world", "kitchen"],
            "unknown world 'kitchen'; available: arena, box_database, lab_room",
        ),
        (
            ["render", "--world", "box_database", "--model", "M9"],
            "unknown model 'M9'; models: M0, M1, M2, M3",
        ),
        (["render", "--pan-tilt", "200,0"], "pan 200.0 deg is outside [-158.9, 158.9] deg"),
        (["render", "--size", "big"], "--size must look like 320x240"),
        (["render", "--at", "1,2"], "--at must be 3 comma-separated numbers"),
    ],
)
def test_bad_input_is_one_clear_line_and_a_nonzero_exit(tmp_path, args, message):
    r = _run(*args, "--out", str(tmp_path))
    assert r.returncode == 2
    assert message in r.stderr
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_demo_runs_an_identification_episode_and_writes_its_figures_and_report(tmp_path):
    """A short demo (a still box facing the robot, the circling baseline, one action): the one-command
    experience writes the paper's figures, the identify JSON and a report that points at them."""
    r = subprocess.run(
        [sys.executable, "-m", "lab", "demo", "--out", str(tmp_path), "--true-model", "2"]
        + ["--mover", "static", "--planner", "circle", "--max-actions", "1", "--max-time", "5"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert str(tmp_path) in r.stdout  # it says where
    res = json.loads((tmp_path / "identify.json").read_text())
    assert res["true_model"] == 2 and res["planner"] == "circle" and res["sim_time_s"] <= 5.5
    assert abs(sum(res["final_posterior"]) - 1.0) < 1e-9
    assert all(h["ptu_state"] in ("tracking", "scanning") for h in res["history"])
    report = (tmp_path / "report.md").read_text()
    assert "The box on the carrier was **M2**" in report
    for fig in ("fig5_pose_and_probabilities.png", "fig7_probabilities.png"):
        assert (tmp_path / fig).is_file() and f"({fig})" in report
    r = _run("demo", "--out", str(tmp_path), "--true-model", "9")
    assert r.returncode == 2 and "unknown true model 9; models: 0..3" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_notebooks_command_lists_them_and_says_what_is_missing(capsys, monkeypatch):
    assert main(["notebooks", "--list"]) == 0
    names = capsys.readouterr().out.split()
    assert names[:6] == [
        "00_simulator_and_stereo.ipynb",
        "01_pose_ekf.ipynb",
        "02_entropy_planning.ipynb",
        "03_grid_search.ipynb",
        "04_real_robot.ipynb",
        "05_localization.ipynb",
    ]
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n: None if n == "jupyterlab" else real(n))
    assert main(["notebooks"]) == 2
    err = capsys.readouterr().err
    assert "JupyterLab is not installed: pip install -e '.[notebooks]'" in err and len(err.splitlines()) == 1
