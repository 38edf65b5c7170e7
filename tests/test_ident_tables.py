"""Lookup tables (the paper's Table I) built from rendered views: content, determinism, the cache
(versioned, atomic, digest-checked, stale detection), bad files and the command line.

The full tables take minutes (`lab tables`); these tests build a few rows with few renders.
"""

import json

import numpy as np
import pytest

from lab.cli import main
from lab.errors import AssetError
from lab.identification import ModelTables, load_model_tables, save_model_tables
from lab.training import (
    TableParams,
    build_model_tables,
    get_databases,
    get_model_tables,
    get_tables,
    load_tables,
    tables_path,
)
from lab.training import tables as tables_module

NAMES = ("M0", "M1", "M2", "M3")
ROWS = (0, 18)  # the unique face (+X) and the opposite, shared, face (-X)
PARAMS = TableParams(repeats=2)


@pytest.fixture(scope="module")
def dbs():
    return get_databases(NAMES, progress=False)


@pytest.fixture(scope="module")
def small(dbs):
    """M1's tables at two training poses, built twice."""
    a = build_model_tables("M1", dbs, PARAMS, viewpoint_indices=ROWS)
    b = build_model_tables("M1", dbs, PARAMS, viewpoint_indices=ROWS)
    return a, b


def test_building_is_deterministic(small):
    a, b = small
    assert a.digest() == b.digest()
    for pa, pb in zip(a.P, b.P, strict=True):
        np.testing.assert_array_equal(pa, pb)


def test_tables_say_which_model_the_unique_face_belongs_to(small, dbs):
    t = small[0]
    assert t.true_model == "M1" and t.names == NAMES
    W = np.array([t.table(j)[list(ROWS)].sum(axis=1) for j in NAMES])  # E[W_ij] at the two rows
    unique, shared = W[:, 0], W[:, 1]
    assert unique[1] >= 15 and unique[1] >= 5 * max(unique[[0, 2, 3]].max(), 1.0), unique
    assert shared.min() >= 5 and shared.max() <= 1.5 * shared.min(), shared  # all explain the shared face
    assert np.all((t.P[0] >= 0) & (t.P[0] <= 1))
    assert np.all(t.P[1][[r for r in range(36) if r not in ROWS]] == 0)  # rows not built stay 0
    # Table I's pose column: the nominal relative pose of the row, 1 m in front of the camera
    assert np.linalg.norm(t.poses[0, :3]) == pytest.approx(1.0, abs=1e-6)


def test_save_and_load_round_trip(small, tmp_path):
    t = small[0]
    path = tmp_path / "M1.npz"
    save_model_tables(t, path)
    u = load_model_tables(path, "M1")
    assert u.digest() == t.digest() and u.names == t.names
    assert not list(tmp_path.glob(".*tmp*"))  # the atomic write left no temporary file


def test_missing_corrupt_empty_and_foreign_files_raise(small, tmp_path):
    t = small[0]
    with pytest.raises(AssetError, match="do not exist"):
        load_model_tables(tmp_path / "nope.npz")
    bad = tmp_path / "garbage.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(AssetError, match="corrupt"):
        load_model_tables(bad)
    # one value changed after writing: the digest catches it
    path = tmp_path / "M1.npz"
    save_model_tables(t, path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["P_1"] = arrays["P_1"].copy()
    arrays["P_1"][0, 0] = 0.5 if arrays["P_1"][0, 0] != 0.5 else 0.25
    np.savez(path, **arrays)
    with pytest.raises(AssetError, match="digest mismatch"):
        load_model_tables(path)
    # no training poses
    empty = ModelTables(
        "M1", NAMES, np.zeros((0, 2)), np.zeros((0, 6)), tuple(np.zeros((0, 5)) for _ in NAMES)
    )
    save_model_tables(empty, path)
    with pytest.raises(AssetError, match="empty"):
        load_model_tables(path)
    # an older format
    save_model_tables(t, path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    meta["format_version"] = 0
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    with pytest.raises(AssetError, match="format 0"):
        load_model_tables(path)
    save_model_tables(t, path)
    with pytest.raises(AssetError, match="hold 'M1', expected 'M2'"):
        load_model_tables(path, "M2")


def test_stale_tables_are_refused_and_rebuilt(small, dbs, tmp_path, monkeypatch):
    t = small[0]
    folder = tmp_path / "tables"
    for n in NAMES:  # M1's real tables stand in for every model's file: only the keys matter here
        meta = dict(t.meta, true_model=n)
        save_model_tables(ModelTables(n, t.names, t.viewpoints, t.poses, t.P, meta), tables_path(n, folder))
    tables = load_tables(NAMES, folder, PARAMS, dbs=dbs)  # current: loads
    assert tables.names == NAMES and tables.W_quantiles.shape[:3] == (4, 4, 36)
    with pytest.raises(AssetError, match="stale: the table or matching parameters changed"):
        load_tables(NAMES, folder, TableParams(repeats=3), dbs=dbs)
    # a database that changed since the tables were built
    other = list(dbs)
    other[2] = type(dbs[2])(**{**dbs[2].__dict__, "points_O": dbs[2].points_O + 1e-4})
    with pytest.raises(AssetError, match=r"stale: the feature database\(s\) M2 changed"):
        load_tables(NAMES, folder, PARAMS, dbs=other)
    # get_tables rebuilds what is stale (the building itself is stubbed: it is tested above)
    built = []

    def fake_build(true_model, dbs_, params, scoring, progress=False):
        built.append(true_model)
        meta = tables_module._key(true_model, dbs_, params, scoring)
        return ModelTables(true_model, t.names, t.viewpoints, t.poses, t.P, meta)

    monkeypatch.setattr(tables_module, "build_model_tables", fake_build)
    get_tables(NAMES, folder, PARAMS, dbs=other, progress=False)
    assert built == list(NAMES)
    load_tables(NAMES, folder, PARAMS, dbs=other)  # now current
    built.clear()
    for lock in folder.rglob("*.lock"):  # left by the builds (they hold nothing)
        lock.unlink()
    get_model_tables("M0", other, folder, PARAMS, progress=False)
    get_tables(NAMES, folder, PARAMS, dbs=other, progress=False)
    assert built == []  # cached: nothing rebuilt
    assert list(folder.rglob("*.lock")) == []  # and read without a lock (no write access needed)
    tables_path("M3", folder).write_bytes(b"corrupt")
    get_tables(NAMES, folder, PARAMS, dbs=other, progress=False)
    assert built == ["M3"]


def test_command_line(tmp_path, capsys):
    assert main(["tables", "M9"]) == 2
    assert "unknown model(s) M9; box models: M0, M1, M2, M3" in capsys.readouterr().err
    assert main(["tables", "--repeats", "0"]) == 2
    assert "--repeats must be at least 1" in capsys.readouterr().err
