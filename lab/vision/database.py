"""Feature databases: the paper's ``B_i = [b_0 ... b_N]``, with descriptors, visibility and a colour model.

A database is what training produced (:mod:`lab.training.databases` renders an object around its
training ring and builds it: identification paper, Sec. III; search paper, Sec. III). This module
holds the data and its file format only: :class:`FeatureDatabase`, and :func:`save_database` /
:func:`load_database`, which write atomically and detect a corrupt or outdated file. Matching a
measured feature set against a database is :mod:`lab.vision.matching`.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lab.errors import AssetError

__all__ = ["FORMAT_VERSION", "POINT_STD_M", "FeatureDatabase", "load_database", "save_database"]

#: Bump when the file layout or the training algorithm changes: older caches are then rebuilt.
FORMAT_VERSION = 1

#: Standard deviation [m] of each axis of a trained database point's own error (the training's
#: stereo error, the same in every frame): the EKF's :class:`lab.estimation.ModelUncertainty`.
#: Chosen where the static-box scenes' NEES lies in its band most often; the trained boxes' points lie
#: 2.4 mm (median) off their faces, 8.8 mm at the 90th percentile: a heavier tail than the filter
#: models. How it was chosen: docs/tuning/database-point-std.md.
POINT_STD_M = 0.002


@dataclass(frozen=True)
class FeatureDatabase:
    """The trained model of one object: 3D SIFT features in O, their visibility, and a colour model.

    Attributes
    ----------
    name : str
    points_O : ndarray, shape (N, 3) [m]
        Feature positions in the object frame O (centre of the object).
    descriptors : ndarray, shape (N, 128), float32
    seen_from : ndarray, shape (N, V), bool
        ``seen_from[l, v]``: feature l was extracted in ring viewpoint v.
    viewpoints : ndarray, shape (V, 2) [rad]
        Azimuth and elevation of each ring viewpoint around O.
    extent : ndarray, shape (3,) [m]
        The object's bounding box size (x, y, z in O).
    histogram : ndarray, shape (bins, bins), float32
        Colour model (sums to 1) in ``meta["colour_space"]``.
    meta : dict
        Format version, parameters, camera, the asset hash the database was built from.
    """

    name: str
    points_O: np.ndarray = field(repr=False)
    descriptors: np.ndarray = field(repr=False)
    seen_from: np.ndarray = field(repr=False)
    viewpoints: np.ndarray = field(repr=False)
    extent: np.ndarray = field(repr=False)
    histogram: np.ndarray = field(repr=False)
    meta: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.points_O)

    @property
    def point_std_m(self) -> float:
        """How well the points know the object: ``meta["point_std_m"]``, else :data:`POINT_STD_M`."""
        return float(self.meta.get("point_std_m", POINT_STD_M))

    def _arrays(self) -> dict[str, np.ndarray]:
        return {
            "points_O": self.points_O,
            "descriptors": self.descriptors,
            "seen_from": self.seen_from,
            "viewpoints": self.viewpoints,
            "extent": self.extent,
            "histogram": self.histogram,
        }

    def digest(self) -> str:
        """SHA-256 of the arrays (detects corruption, and shows that two trainings are identical)."""
        h = hashlib.sha256()
        for k, a in sorted(self._arrays().items()):
            h.update(k.encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()


# --- persistence -----------------------------------------------------------------------------------


def save_database(db: FeatureDatabase, path: Path) -> None:
    """Write a database atomically: arrays + JSON metadata (with the arrays' digest) in one .npz."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = dict(db.meta, digest=db.digest())
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), **db._arrays())
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def load_database(path: Path, name: str | None = None) -> FeatureDatabase:
    """Read a database, checking its format version and digest; raises AssetError when corrupt."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"feature database {path} does not exist (build it with `lab train`)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {
                k: z[k] for k in ("points_O", "descriptors", "seen_from", "viewpoints", "extent", "histogram")
            }
    except Exception as e:  # zip, JSON or missing-key damage
        raise AssetError(
            f"feature database {path} is corrupt ({type(e).__name__}: {e}); rebuild with `lab train`"
        ) from None
    if meta.get("format_version") != FORMAT_VERSION:
        raise AssetError(
            f"feature database {path} has format {meta.get('format_version')}, expected {FORMAT_VERSION}"
        )
    db = FeatureDatabase(meta["name"], meta=meta, **arrays)
    if db.digest() != meta.get("digest"):
        raise AssetError(f"feature database {path} is corrupt (digest mismatch); rebuild with `lab train`")
    if name is not None and db.name != name:
        raise AssetError(f"feature database {path} holds {db.name!r}, expected {name!r}")
    return db
