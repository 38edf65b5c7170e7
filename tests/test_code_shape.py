"""The code-shape rules of docs/architecture.md hold for ``lab/`` (see :mod:`code_shape`)."""

from __future__ import annotations

from pathlib import Path

import code_shape

LAB = Path(__file__).resolve().parent.parent / "lab"

#: Modules over :data:`code_shape.MAX_MODULE_LINES` lines, each with the one idea it holds.
ONE_IDEA: dict[str, str] = {
    "lab/hardware/robot.py": "HardwareRobot, the Robot contract on the real devices: one class whose "
    "lifecycle, safety states and servo/watchdog thread share one lock and one state machine",
    "lab/localization/filter.py": "the localizer's filter: its config, its estimate and update records, the "
    "pose clone, and Localizer",
}


def test_no_private_name_is_imported_across_modules():
    assert code_shape.private_imports(LAB) == []


def test_no_private_attribute_of_another_module_is_read():
    assert code_shape.private_attribute_reads(LAB) == []


def test_functions_are_short():
    assert code_shape.long_functions(LAB) == []


def test_modules_are_short_or_hold_one_idea():
    long = code_shape.long_modules(LAB)
    assert {p: n for p, n in long.items() if p not in ONE_IDEA} == {}
    assert set(ONE_IDEA) <= set(long), "an allow-listed module is short now: drop it from ONE_IDEA"


def test_no_docstring_or_comment_names_a_seed_or_a_trial_count():
    assert code_shape.tuning_records(LAB) == []
