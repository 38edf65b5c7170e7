"""The landmark map: fixed textured posters with known poses in the room, for localization.

A landmark is a flat textured panel on a wall (the lab room's posters). Its frame L has its origin at
the panel's centre and the room's yaw of the body (``docs/conventions.md``: z up); ``normal_W`` is the
unit direction, in the floor plane, in which its printed face looks into the room. The localizer
(:mod:`lab.localization`) needs, per landmark, ``G_WL`` and its feature database ``B_L``
(3D SIFT features in L, trained like the objects' in :mod:`lab.training.landmarks`).

This module is data only: the map is built from a scene file or a hardware landmark file by
:mod:`lab.training.landmarks`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from lab.errors import ConfigError
from lab.geometry import Rz, se3
from lab.vision.database import FeatureDatabase

__all__ = ["Landmark", "LandmarkMap"]


@dataclass(frozen=True)
class Landmark:
    """One landmark: its name, pose in the world and printed size, and its feature database.

    Attributes
    ----------
    name : str
    centre_W : tuple of 3 floats [m]
        The panel's centre in the world W.
    yaw : float [rad]
        Rotation of L about the world's z axis.
    size : tuple of 3 floats [m]
        Panel extent along L's x, y, z (one of x, y is its thickness).
    normal_W : tuple of 2 floats
        Unit vector (x, y) in W in which the printed face looks (into the room).
    database : FeatureDatabase or None
        Its 3D SIFT features in L (None until trained).
    survey_sigma_m, survey_sigma_rad : float [m], [rad]
        How well ``centre_W`` (x and y, each) and ``yaw`` are known: the standard deviations of a map
        measured in a room (a tape and a protractor). 0 (the default): exact, as a scene's own posters
        are; the localizer holds the landmark fixed. Above 0 the localizer carries the landmark's
        planar pose in its state, seeded here with these, and refines it from its sightings
        (:mod:`lab.localization.posters`).
    """

    name: str
    centre_W: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]
    normal_W: tuple[float, float]
    database: FeatureDatabase | None = field(default=None, repr=False, compare=False)
    survey_sigma_m: float = 0.0
    survey_sigma_rad: float = 0.0

    def __post_init__(self):
        for k in ("survey_sigma_m", "survey_sigma_rad"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"Landmark {self.name!r}: {k} must be a finite number >= 0, got {v!r}")

    @property
    def surveyed(self) -> bool:
        """Whether the landmark's pose is known only to its survey's accuracy (a sigma above 0)."""
        return self.survey_sigma_m > 0 or self.survey_sigma_rad > 0

    @property
    def G_WL(self) -> np.ndarray:
        """The landmark frame L in the world, 4x4."""
        return se3(Rz(self.yaw), self.centre_W)

    @property
    def planar(self) -> np.ndarray:
        """``l = [x, y, yaw]`` of L in the floor plane: the localizer's landmark (fixed, or its state's
        seed when :attr:`surveyed`)."""
        return np.array([self.centre_W[0], self.centre_W[1], self.yaw])

    @property
    def width_m(self) -> float:
        """The printed face's width (the larger of its horizontal extents)."""
        return max(self.size[0], self.size[1])

    def face_points_L(self, n: int = 15) -> np.ndarray:
        """An ``n`` x ``n`` grid of points (n*n, 3) [m] spanning the printed face, in L.

        The face is the panel's side across its thin axis (x or y of L, whichever is smaller) that
        looks along ``normal_W``; the grid runs edge to edge over its width and height.
        """
        thin = 0 if self.size[0] <= self.size[1] else 1
        wide = 1 - thin
        n_L = Rz(self.yaw)[:2, thin]
        sign = 1.0 if float(np.dot(n_L, self.normal_W)) >= 0.0 else -1.0
        s = np.linspace(-0.5, 0.5, int(n))
        a, b = np.meshgrid(s, s, indexing="ij")
        P = np.zeros((a.size, 3))
        P[:, thin] = sign * 0.5 * self.size[thin]
        P[:, wide] = a.ravel() * self.size[wide]
        P[:, 2] = b.ravel() * self.size[2]
        return P

    def facing(self, xy) -> float:
        """Cosine of the angle between the face's normal and the direction from it to ``xy``."""
        d = np.asarray(xy, float)[:2] - np.asarray(self.centre_W[:2])
        r = float(np.hypot(*d))
        return 0.0 if r < 1e-9 else float(np.dot(d, self.normal_W) / r)


def inward_normal(centre_xy, yaw: float, size) -> tuple[float, float]:
    """The face normal of a thin panel that points towards the room's centre (the origin).

    The thin axis of the panel (x or y of L, whichever is smaller) is its normal; of its two signs the
    one facing the origin is the printed face the room sees.
    """
    axis = 0 if size[0] <= size[1] else 1
    n = Rz(yaw)[:2, axis]
    if np.dot(n, -np.asarray(centre_xy[:2], float)) < 0:
        n = -n
    return (float(n[0]), float(n[1]))


@dataclass(frozen=True)
class LandmarkMap:
    """The landmarks of a room, by name, and the room's floor extent.

    Attributes
    ----------
    landmarks : tuple of Landmark
    room_size : tuple of 2 floats [m]
        The room's x and y extent, centred on the origin.
    source : str
        Where the map came from (a scene or a file), for messages.
    joint_prior : (tuple of str, ndarray (3n, 3n)) or None
        A room surveyed once (:mod:`lab.localization.stored_survey`): the posters' names and the joint
        covariance of their planar poses, with which the localizer seeds them all at once
        (:meth:`~lab.localization.Localizer.seed_posters`); None: each poster joins at its first sighting
        with its own survey.
    """

    landmarks: tuple[Landmark, ...]
    room_size: tuple[float, float]
    source: str = ""
    joint_prior: tuple | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.landmarks)

    def __iter__(self):
        return iter(self.landmarks)

    def names(self) -> list[str]:
        return [lm.name for lm in self.landmarks]

    def get(self, name: str) -> Landmark:
        for lm in self.landmarks:
            if lm.name == name:
                return lm
        raise KeyError(name)

    @property
    def trained(self) -> bool:
        return all(lm.database is not None for lm in self.landmarks)

    def surveyed(self, sigma_m: float, sigma_rad: float) -> LandmarkMap:
        """This map with every landmark's pose stated to be known to ``sigma_m`` [m] (x and y, each) and
        ``sigma_rad`` [rad] (yaw): a map measured in a room (:attr:`Landmark.survey_sigma_m`); the
        poses themselves are kept."""
        sm, sr = float(sigma_m), float(sigma_rad)
        lms = tuple(replace(lm, survey_sigma_m=sm, survey_sigma_rad=sr) for lm in self)
        return replace(self, landmarks=lms)

    def bearing_in_robot(self, lm: Landmark, x: np.ndarray) -> tuple[float, float]:
        """Range [m] and bearing [rad] of landmark ``lm``'s centre from the planar pose ``x``."""
        dx, dy = lm.centre_W[0] - x[0], lm.centre_W[1] - x[1]
        return math.hypot(dx, dy), float(np.arctan2(dy, dx) - x[2])
