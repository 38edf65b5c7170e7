"""Files written atomically (lab.io): a reader sees the old file or the new one, never a part."""

import os
import stat

import pytest

from lab.io import atomic_output, write_json_atomic


def test_atomic_output_replaces_the_file_only_when_the_block_ends(tmp_path):
    target = tmp_path / "sub" / "scores.csv"
    with atomic_output(target) as tmp:
        tmp.write_text("student,total\nalice,3\n")
        assert not target.exists()  # nothing at the target while it is written
    assert target.read_text() == "student,total\nalice,3\n"
    assert stat.S_IMODE(target.stat().st_mode) == 0o600  # the owner's only, as mkstemp makes it
    assert os.listdir(target.parent) == ["scores.csv"]  # no temporary file left


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = write_json_atomic(tmp_path / "results.json", {"score": 1})
    with pytest.raises(RuntimeError), atomic_output(target) as tmp:
        tmp.write_text("{half")
        raise RuntimeError("the writer failed")
    assert target.read_text() == '{\n  "score": 1\n}'
    assert os.listdir(tmp_path) == ["results.json"]
