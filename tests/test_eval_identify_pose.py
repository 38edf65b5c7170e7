"""lab eval identify's final pose columns: the error and stated deviation per episode, the median, 90th
percentile and worst over the identified episodes, and the confidently wrong count by issue 52's bar."""

import numpy as np
import pytest

from lab.eval.sweep import (
    IDENTIFY,
    confidently_wrong_pose,
    final_pose_quantile,
    with_pose_columns,
    write_report,
)


def test_the_columns_come_from_pose_error_and_pose_estimate():
    res = {
        "pose_error": {"translation_m": 0.012, "rotation_deg": 3.5},
        "pose_estimate": {"position_std_m": 0.004, "orientation_std_deg": 1.2, "model": 2},
    }
    assert with_pose_columns(res) == {
        "position_error_m": 0.012,
        "orientation_error_deg": 3.5,
        "std_position_m": 0.004,
        "std_orientation_deg": 1.2,
    }
    assert set(with_pose_columns({"pose_error": None, "pose_estimate": None}).values()) == {None}


def test_confidently_wrong_is_beyond_5_cm_or_10_deg_with_a_stated_deviation_under_a_third():
    off = {"position_error_m": 0.06, "orientation_error_deg": 2.0, "std_orientation_deg": 0.1}
    assert confidently_wrong_pose({**off, "std_position_m": 0.019})
    assert not confidently_wrong_pose({**off, "std_position_m": 0.021})
    turned = {"position_error_m": 0.01, "orientation_error_deg": 12.0, "std_position_m": 0.001}
    assert confidently_wrong_pose({**turned, "std_orientation_deg": "3.9"})  # CSV strings too
    assert not confidently_wrong_pose({**turned, "std_orientation_deg": 4.1})
    assert not confidently_wrong_pose({**turned, "std_orientation_deg": ""})  # nothing stated
    assert not confidently_wrong_pose({"position_error_m": 0.049, "std_position_m": 0.0})  # within the bar


def _rows():
    rng = np.random.default_rng(3)
    pos, rot = rng.uniform(0.001, 0.05, 20), rng.uniform(0.1, 20.0, 20)
    rows = [
        {
            "success": True,
            "position_error_m": p,
            "orientation_error_deg": o,
            "std_position_m": 0.005,
            "std_orientation_deg": 1.0,
        }
        for p, o in zip(pos, rot, strict=True)
    ]
    rows.append({"success": False, "position_error_m": 0.9, "orientation_error_deg": 170.0})  # not counted
    return rows, pos, rot


def test_the_quantiles_are_numpys_over_the_identified_episodes():
    rows, pos, rot = _rows()
    for q in (0.5, 0.9, 1.0):
        p, o = final_pose_quantile(rows, q)
        assert p == pytest.approx(100 * np.quantile(pos, q)) and o == pytest.approx(np.quantile(rot, q))
    assert final_pose_quantile([{"success": False, "position_error_m": 0.1}], 0.5) is None


def test_the_report_shows_them(tmp_path):
    rows, pos, rot = _rows()
    for i, r in enumerate(rows):
        r.update(key=f"k{i}", planner="lut", mover="evasive", sensing="room", localization="odometry")
        r.update(seed=i, error="")
        r.update(actions=3, max_actions=8, sim_time_s=20.0)
    n_wrong = sum(
        ((p > 0.05) and 0.005 < p / 3) or (o > 10 and 1.0 < o / 3) for p, o in zip(pos, rot, strict=True)
    )
    write_report(tmp_path, rows, IDENTIFY)
    text = (tmp_path / "report.md").read_text()
    assert "final pose median" in text and "confidently wrong" in text
    p50, o50 = final_pose_quantile(rows, 0.5)
    p90, o90 = final_pose_quantile(rows, 0.9)
    line = next(ln for ln in text.splitlines() if ln.startswith("| lut | evasive | room | odometry |"))
    assert f"{p50:.2f} cm / {o50:.1f}°" in line and f"{p90:.2f} cm / {o90:.1f}°" in line
    assert line.split("|")[-3].strip() == str(n_wrong) and n_wrong > 0
