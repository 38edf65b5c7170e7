"""Seeing landmarks: finding a map's posters in stereo frames and turning each fit into a measurement.

A poster on a wall, whose pose ``G_WL`` is known (:mod:`lab.localization.landmarks`), is found in a
stereo frame by matching its 3D SIFT database and fitting ``G_CL`` with RANSAC + Gauss-Newton
(:func:`lab.estimation.fit.ransac_pose`, the objects' own initialisation); through the pan-tilt
transform ``G_RL = G_RC(pan, tilt) G_CL`` it gives the landmark's planar pose in the robot frame, the
measurement ``z`` (:func:`~lab.localization.models.observation_of`). A fit whose face lies mostly
outside the image is not used (:func:`face_share_in_image`, ``LocalizerConfig.min_face_in_image``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lab.errors import ConfigError
from lab.estimation.fit import ransac_pose
from lab.geometry import Pose2D, pose6_to_G, se3_inv, transform_points
from lab.localization.filter import LocalizerConfig
from lab.localization.landmarks import Landmark, LandmarkMap
from lab.localization.models import observation_of
from lab.robot import StereoFrame
from lab.vision.matching import Matcher
from lab.vision.stereo import Features3D, StereoParams, sift, stereo_features

__all__ = ["LandmarkObservation", "LandmarkObserver", "face_share_in_image"]


def face_share_in_image(landmark: Landmark, G_CL: np.ndarray, camera, n: int = 15) -> float:
    """The share (0-1) of ``landmark``'s printed face that projects into ``camera``'s image when the
    landmark frame L is at ``G_CL`` in the camera frame C: of an ``n`` x ``n`` grid of points spanning
    the face (:meth:`Landmark.face_points_L`), those in front of the camera whose pixel lies inside the
    image."""
    P = transform_points(G_CL, landmark.face_points_L(n))
    front = P[:, 2] > 1e-3
    if not front.any():
        return 0.0
    uv = camera.project(P[front])
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= camera.height)
    return float(np.count_nonzero(inside)) / len(P)


@dataclass(frozen=True)
class LandmarkObservation:
    """A landmark found in a frame: its fitted ``G_CL``, the measurement ``z`` and covariance ``Q``;
    ``Sigma_rv`` is the fit's own covariance over ``[t_CL, phi]`` (:func:`observation_of`)."""

    landmark: Landmark
    G_CL: np.ndarray = field(repr=False)
    z: np.ndarray = field(repr=False)
    Q: np.ndarray = field(repr=False)
    n_inliers: int = 0
    Sigma_rv: np.ndarray | None = field(default=None, repr=False)


class LandmarkObserver:
    """Finds the landmarks of a map in stereo frames (features, database matching, RANSAC).

    Parameters
    ----------
    landmarks : LandmarkMap
        A trained map (every landmark has a database).
    config : LocalizerConfig
    rng : numpy.random.Generator
        Seeds RANSAC's minimal samples.
    """

    def __init__(self, landmarks: LandmarkMap, config: LocalizerConfig, rng: np.random.Generator):
        if not landmarks.trained:
            raise ConfigError(f"landmark map {landmarks.source} is not trained (lab.training.landmarks)")
        self.map, self.config, self.rng = landmarks, config, rng
        self.matchers = {lm.name: Matcher(lm.database, method="brute") for lm in landmarks}
        self._params = StereoParams()
        self._det = sift(self._params.n_features, self._params.contrast_threshold)
        self.n_partial = 0  # fits dropped: too little of the face in the image

    def candidates(self, x, frame_or_G_RC, camera=None, margin_px: float = 20.0) -> list[Landmark]:
        """Landmarks whose centre the camera should see from pose ``x`` (in range, facing, in the image)."""
        if isinstance(frame_or_G_RC, StereoFrame):
            G_RC, camera = frame_or_G_RC.G_RC, frame_or_G_RC.camera
        else:
            G_RC = frame_or_G_RC
        G_WC = Pose2D(*x).G() @ G_RC
        G_CW = se3_inv(G_WC)
        out = []
        for lm in self.map:
            rng_m, _ = self.map.bearing_in_robot(lm, x)
            if rng_m > self.config.max_range_m or lm.facing(x[:2]) < self.config.min_facing:
                continue
            p = transform_points(G_CW, np.asarray(lm.centre_W))
            if p[2] < 0.3:
                continue
            u, v = camera.project(p[None])[0]
            if -margin_px <= u <= camera.width + margin_px and -margin_px <= v <= camera.height + margin_px:
                out.append(lm)
        return out

    def features(self, frame: StereoFrame) -> Features3D:
        return stereo_features(
            frame.left, frame.right, frame.camera, self._params, t=frame.t, detector=self._det
        )

    def observe(self, frame: StereoFrame, candidates: list[Landmark]) -> list[LandmarkObservation]:
        """Fit every candidate landmark in the frame; those with enough RANSAC inliers whose fitted face
        lies enough in the image (``min_face_in_image``). ``n_partial`` counts the fits dropped for the
        latter."""
        if not candidates:
            return []
        f = self.features(frame)
        out = []
        for lm in candidates:
            corr = self.matchers[lm.name].match(f)
            if corr.n_matched < self.config.min_inliers:
                continue
            d, b, S = corr.pairs(f, lm.database)
            res = ransac_pose(d, b, S, self.rng, self.config.ransac)
            if not res.success or res.n_inliers < self.config.min_inliers:
                continue
            G_CL = pose6_to_G(res.mu)
            if face_share_in_image(lm, G_CL, frame.camera) < self.config.min_face_in_image:
                self.n_partial += 1
                continue
            z, Q = observation_of(frame.G_RC, G_CL, res.Sigma_rv)
            out.append(LandmarkObservation(lm, G_CL, z, Q, res.n_inliers, res.Sigma_rv))
        return out
