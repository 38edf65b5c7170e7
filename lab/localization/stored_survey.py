r"""A room surveyed once: the posters as a survey tour refined them, kept in a file for every later run.

A map measured with a tape is off by its survey's error, poster by poster, and a run that starts from
it refines only the posters it happens to see (:mod:`lab.localization.posters`). A survey tour
(:mod:`lab.localization.survey_tour`) ties every poster to the others, but it costs minutes of the
robot's time. A room's posters do not move between runs, so the tour is worth driving once: its
refined posters, with their joint covariance, become the map every later run starts from.

What is kept is the posters' block of the localizer's state after the tour (marginalizing a Gaussian
is taking its block)::

    l = [l_1, ..., l_n],   l_j = [x_j, y_j, psi_j]      P_ll = Cov(l)   (3n x 3n)

Posters the tour never saw keep their survey (``diag(sm^2, sm^2, sr^2)``, independent of the rest).
The correlations matter: after a tour the posters' *shape* is known to a few millimetres while their
common frame is still only as good as all the surveys together (:mod:`lab.localization.survey_limit`),
and the covariance says exactly that. A later run seeds its state with ``(l, P_ll)`` at once
(:meth:`~lab.localization.Localizer.seed_posters`) instead of each poster's survey at its first sighting.

The robot's own constants estimated on the tour (the camera's yaw on the base, the range scale) are not
kept: they are the robot's, a later run estimates them again, and the posters' block already carries
their share of the uncertainty.

The file is JSON (``lab survey --out FILE`` writes it, ``lab search --survey FILE`` reads it), written
atomically, with a format version and a SHA-256 of its content: a file cut short or edited by hand is
refused, and so is a survey of another map (the map's own poses are kept in the file and must match
the map the run loads: a re-measured poster means the room must be surveyed again).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from lab.errors import ConfigError
from lab.geometry import wrap_angle
from lab.io import write_json_atomic
from lab.localization.landmarks import LandmarkMap
from lab.localization.posters import survey_prior

__all__ = ["FORMAT", "StoredSurvey", "load_survey", "survey_of"]

FORMAT = ("lab-room-survey", 1)
_MAP_TOLERANCE = (1e-4, 1e-5)  # [m], [rad]: the file's map poses against the loaded map's (rounding only)


@dataclass(frozen=True)
class StoredSurvey:
    """The posters of a room as a survey tour refined them.

    Attributes
    ----------
    names : tuple of str
        The posters, in the order of ``poses`` and ``covariance``'s blocks.
    poses : ndarray (n, 3)
        Each poster's refined planar pose ``[x, y, yaw]`` [m, m, rad].
    covariance : ndarray (3n, 3n)
        Their joint covariance.
    map_poses : ndarray (n, 3)
        The map's poses the tour started from (the surveyed map): a run refuses the file for another map.
    source : str
        The map's source, for messages.
    record : dict
        What made it (the tour's stands, sightings and time; in the simulator the posters' errors before
        and after against the scene's truth, evaluation only).
    """

    names: tuple[str, ...]
    poses: np.ndarray
    covariance: np.ndarray
    map_poses: np.ndarray
    source: str = ""
    record: dict | None = None

    def __post_init__(self):
        n = len(self.names)
        if len(set(self.names)) != n or n == 0:
            raise ConfigError(
                f"a stored survey needs at least one poster, each named once; got {self.names!r}"
            )
        for k, shape in (("poses", (n, 3)), ("map_poses", (n, 3)), ("covariance", (3 * n, 3 * n))):
            a = np.asarray(getattr(self, k), float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise ConfigError(
                    f"a stored survey's {k} must be {shape} finite numbers, got shape {a.shape}"
                )
            object.__setattr__(self, k, a)
        C = self.covariance
        if not np.allclose(C, C.T, atol=1e-12) or np.linalg.eigvalsh(C).min() <= 0:
            raise ConfigError("a stored survey's covariance must be symmetric positive definite")

    def sigma(self, i: int) -> tuple[float, float]:
        """Poster ``i``'s marginal deviations: position (the larger of x, y) [m] and yaw [rad]."""
        d = np.diag(self.covariance)[3 * i : 3 * i + 3]
        return math.sqrt(max(d[0], d[1])), math.sqrt(d[2])

    # --- the map a run starts from ---------------------------------------------------------------------
    def applied_to(self, landmarks: LandmarkMap) -> LandmarkMap:
        """``landmarks`` (the map the run loaded, the one this survey was made on) with each poster at its
        refined pose and stated to its marginal deviations, and the joint prior for
        :meth:`~lab.localization.Localizer.seed_posters` (:attr:`LandmarkMap.joint_prior`).

        Raises
        ------
        ConfigError
            The map is not the one surveyed: another set of posters, or a poster's pose moved.
        """
        if sorted(landmarks.names()) != sorted(self.names):
            raise ConfigError(
                f"the stored survey ({self.source}) has posters {', '.join(sorted(self.names))}; the map "
                f"{landmarks.source} has {', '.join(sorted(landmarks.names()))}: survey this room again"
            )
        out = []
        for lm in landmarks:
            i = self.names.index(lm.name)
            d = lm.planar - self.map_poses[i]
            d[2] = wrap_angle(d[2])
            if np.any(np.abs(d[:2]) > _MAP_TOLERANCE[0]) or abs(d[2]) > _MAP_TOLERANCE[1]:
                raise ConfigError(
                    f"the stored survey ({self.source}) was made on another map: {lm.name} is "
                    f"{100 * math.hypot(d[0], d[1]):.1f} cm / {math.degrees(d[2]):.2f} deg from where the "
                    f"map "
                    f"{landmarks.source} puts it; survey this room again"
                )
            x, y, yaw = self.poses[i]
            turn = float(wrap_angle(yaw - lm.yaw))
            c, s = math.cos(turn), math.sin(turn)
            n = (c * lm.normal_W[0] - s * lm.normal_W[1], s * lm.normal_W[0] + c * lm.normal_W[1])
            sm, sr = self.sigma(i)
            out.append(
                replace(lm, centre_W=(float(x), float(y), lm.centre_W[2]), yaw=float(yaw), normal_W=n,
                        survey_sigma_m=sm, survey_sigma_rad=sr)
            )  # fmt: skip
        order = [self.names.index(lm.name) for lm in landmarks]
        idx = np.concatenate([[3 * i, 3 * i + 1, 3 * i + 2] for i in order])
        prior = (tuple(lm.name for lm in landmarks), self.covariance[np.ix_(idx, idx)])
        return replace(landmarks, landmarks=tuple(out), source=f"{landmarks.source} (surveyed once)",
                       joint_prior=prior)  # fmt: skip

    # --- the file ---------------------------------------------------------------------------------------
    def _content(self) -> dict:
        return {
            "format": FORMAT[0],
            "version": FORMAT[1],
            "source": self.source,
            "names": list(self.names),
            "poses": self.poses.tolist(),
            "map_poses": self.map_poses.tolist(),
            "covariance": self.covariance.tolist(),
            "record": self.record or {},
        }

    def save(self, path: str | Path) -> Path:
        """Write the survey to ``path`` (JSON, atomically, with the SHA-256 of its content)."""
        data = self._content()
        data["sha256"] = _digest(data)
        return write_json_atomic(path, data)


def _digest(content: dict) -> str:
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def load_survey(path: str | Path) -> StoredSurvey:
    """The stored survey in ``path`` (:meth:`StoredSurvey.save`'s file).

    Raises
    ------
    ConfigError
        The file is missing, not this format or version, or corrupt (its content does not match its
        SHA-256, a field is missing or malformed): one line naming the file.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such survey file (make one with `lab survey --out {path}`)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"{path}: not a survey file (unreadable JSON: {e})") from None
    if not isinstance(data, dict) or (data.get("format"), data.get("version")) != FORMAT:
        got = (data.get("format"), data.get("version")) if isinstance(data, dict) else type(data).__name__
        raise ConfigError(
            f"{path}: not a survey file of format {FORMAT[0]!r} version {FORMAT[1]} (got {got!r})"
        )
    digest = data.pop("sha256", None)
    if digest != _digest(data):
        raise ConfigError(f"{path}: the survey file is corrupt (its content does not match its SHA-256)")
    try:
        return StoredSurvey(
            tuple(data["names"]), np.array(data["poses"], float), np.array(data["covariance"], float),
            np.array(data["map_poses"], float), str(data["source"]), dict(data["record"]),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(f"{path}: the survey file is malformed ({e})") from None


def survey_of(localizer, landmarks: LandmarkMap, record: dict | None = None) -> StoredSurvey:
    """The posters of ``landmarks`` as ``localizer`` holds them now (after a tour): the state's poster
    blocks and their joint covariance; a poster never seen keeps its survey (independent of the rest)."""
    names = tuple(lm.name for lm in landmarks if lm.surveyed)
    if not names:
        raise ConfigError(
            f"the map {landmarks.source} is taken as exact (no survey sigma): nothing to survey"
        )
    n = len(names)
    poses, C = np.zeros((n, 3)), np.zeros((3 * n, 3 * n))
    idx = [localizer.posters.index_of(landmarks.get(k)) for k in names]
    seen = [i for i, j in enumerate(idx) if j is not None]
    rows = np.concatenate([[idx[i], idx[i] + 1, idx[i] + 2] for i in seen]) if seen else np.zeros(0, int)
    cols = np.concatenate([[3 * i, 3 * i + 1, 3 * i + 2] for i in seen]) if seen else np.zeros(0, int)
    C[np.ix_(cols, cols)] = localizer.P[np.ix_(rows, rows)]
    for i, k in enumerate(names):
        if idx[i] is None:
            poses[i], C[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = survey_prior(landmarks.get(k))
        else:
            poses[i] = localizer.s[idx[i] : idx[i] + 3]
    C = 0.5 * (C + C.T)
    map_poses = np.array([landmarks.get(k).planar for k in names])
    return StoredSurvey(names, poses, C, map_poses, landmarks.source, record)
