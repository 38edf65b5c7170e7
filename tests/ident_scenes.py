"""Synthetic scenes for the identification tests: box databases, measured feature sets, hypotheses.

No rendering: the features are the databases' own points seen from a pose, with stereo-like noise and
slightly perturbed descriptors (so that the scoring's descriptor test, gate and clutter term all act).
"""

import math

import numpy as np

from lab.estimation.synthetic import stereo_covariance
from lab.geometry import Pose2D, Rz, se3, se3_inv, transform_points
from lab.identification import ModelHypotheses, pose_estimate_rv
from lab.identification.synthetic import synthetic_box_databases, synthetic_tables
from lab.robot import StereoCamera
from lab.vision import Features3D

CAMERA = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))
CENTRE_W = np.array([0.0, 0.0, 0.49])
SIGMA = np.diag([2e-4] * 3 + [1e-3] * 3)  # a tracked pose: 1.4 cm, 1.8 deg


def databases(L=4, seed=0):
    return synthetic_box_databases(L, np.random.default_rng(seed))


def tables(dbs):
    return synthetic_tables(dbs)


def camera_at(azimuth_deg, radius=1.0, height=0.7):
    """A camera in W on a circle around the box centre, looking at it (x right, y down, z forward)."""
    a = math.radians(azimuth_deg)
    eye = CENTRE_W + np.array([radius * math.cos(a), radius * math.sin(a), height - CENTRE_W[2]])
    z = CENTRE_W - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    return se3(np.stack([x, np.cross(z, x), z], axis=1), eye)


def box_pose(yaw_deg=0.0):
    """The box's frame O in W: centre at CENTRE_W, turned by yaw (its unique +X face towards yaw)."""
    return se3(Rz(math.radians(yaw_deg)), CENTRE_W)


def observe(db, G_WO, G_WC, rng, clutter=20, p_detect=1.0):
    """Features3D of ``db``'s box at G_WO seen by a camera at G_WC: the visible database features (by
    the nearest ring viewpoint's seen_from, inside the image), noisy, plus ``clutter`` random points."""
    G_CO = se3_inv(G_WC) @ G_WO
    p_O = transform_points(se3_inv(G_CO), np.zeros((1, 3)))[0]
    az = math.atan2(p_O[1], p_O[0])
    v = int(np.argmin(np.abs(np.angle(np.exp(1j * (db.viewpoints[:, 0] - az))))))
    idx = np.flatnonzero(db.seen_from[:, v] & (rng.random(len(db)) < p_detect))
    p = transform_points(G_CO, db.points_O[idx])
    uv = CAMERA.project(p)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < CAMERA.width) & (uv[:, 1] >= 0) & (uv[:, 1] < CAMERA.height)
    idx, p = idx[inside], p[inside]
    S = stereo_covariance(p, CAMERA.fx, CAMERA.baseline, 0.3, 0.5)
    L = np.linalg.cholesky(S)
    d = p + np.einsum("nab,nb->na", L, rng.standard_normal(p.shape))
    desc = db.descriptors[idx] + rng.normal(0.0, 8.0, (len(idx), 128)).astype(np.float32)
    # clutter: random points 1-3 m in front, random descriptors
    cz = rng.uniform(1.0, 3.0, clutter)
    cp = np.stack([rng.uniform(-0.5, 0.5, clutter) * cz, rng.uniform(-0.4, 0.4, clutter) * cz, cz], axis=1)
    cd = rng.random((clutter, 128)).astype(np.float32) ** 3
    cd = 512.0 * cd / np.linalg.norm(cd, axis=1, keepdims=True)
    pts = np.concatenate([d, cp])
    cov = np.concatenate([S, stereo_covariance(cp, CAMERA.fx, CAMERA.baseline, 0.3, 0.5)])
    uv_all = CAMERA.project(pts)
    disp = CAMERA.fx * CAMERA.baseline / pts[:, 2]
    return Features3D(pts, np.concatenate([desc, cd]).astype(np.float32), uv_all, disp, cov)


def estimate(G_WO, G_WC, Sigma=SIGMA):
    """The object's pose in the camera as a PoseEstimate (an exact filter estimate, for the tests)."""
    from lab.geometry import G_to_pose6

    return pose_estimate_rv(G_to_pose6(se3_inv(G_WC) @ G_WO), Sigma)


def hypotheses(P, yaw_deg=0.0, Sigma=SIGMA, yaws=None):
    """One pose per model (all at the same box pose unless ``yaws`` gives one per model)."""
    L = len(P)
    yaws = [yaw_deg] * L if yaws is None else yaws
    return ModelHypotheses.one_pose_each(P, np.stack([box_pose(y) for y in yaws]), np.stack([Sigma] * L))


__all__ = ["CAMERA", "Pose2D", "box_pose", "camera_at", "databases", "estimate", "hypotheses", "observe"]
