"""Synthetic scenes shared by the EKF tests and benchmark: a 0.28 m cube seen by a stereo pair.

Ground truth is built in the world frame with lab.geometry, independently of the filter's motion
model: camera in world = robot pose (Pose2D) @ pan-tilt G_RC; object in camera = inv(camera) @ object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lab.estimation.synthetic import box_surface_points, noisy_points, stereo_covariance, visible_points
from lab.geometry import G_to_pose6, Pose2D, euler_zyx_to_R, pose6_to_G, se3, se3_inv
from lab.robot import StereoCamera

CAMERA = StereoCamera.from_fov(320, 240, 60.0, baseline=0.12)  # f = 207.8 px, b = 0.12 m
SIGMA_D_PX = 0.3
SIGMA_PX = 0.5
CUBE = 0.28


def random_pose_in_view(rng, z_range=(0.8, 1.5), max_abs_beta=1.0) -> np.ndarray:
    """A pose X of the cube in C: in front of the camera, inside the field of view, away from gimbal lock."""
    z = rng.uniform(*z_range)
    x, y = rng.uniform(-0.2, 0.2, 2) * z
    a, g = rng.uniform(-np.pi, np.pi, 2)
    b = rng.uniform(-max_abs_beta, max_abs_beta)
    return np.array([x, y, z, a, b, g])


@dataclass
class Frame:
    d_C: np.ndarray
    b_O: np.ndarray
    Sigma_d: np.ndarray
    wrong: np.ndarray  # True where the match is deliberately wrong


def observe(rng, X_true, b_O, normals_O, n_max=50, outlier_frac=0.0) -> Frame:
    """Matched features of the cube at pose X_true (visible ones, at most n_max), stereo-like noise,
    and a fraction of wrong matches (the measured point of another database feature)."""
    G_CO = pose6_to_G(X_true)
    vis = np.flatnonzero(visible_points(b_O, normals_O, G_CO, CAMERA.K, (CAMERA.width, CAMERA.height)))
    idx = rng.permutation(vis)[:n_max]
    p_C = b_O[idx] @ G_CO[:3, :3].T + G_CO[:3, 3]
    Sigma = stereo_covariance(p_C, CAMERA.fx, CAMERA.baseline, SIGMA_D_PX, SIGMA_PX)
    d_C = noisy_points(rng, p_C, Sigma)
    b_match = b_O[idx].copy()
    wrong = rng.random(len(idx)) < outlier_frac
    for j in np.flatnonzero(wrong):  # a wrong correspondence: some other database feature, far from this one
        far = np.flatnonzero(np.linalg.norm(b_O - b_O[idx[j]], axis=1) > 0.1)
        b_match[j] = b_O[rng.choice(far)]
    return Frame(d_C, b_match, Sigma, wrong)


def cube(rng, n_per_face=40):
    return box_surface_points(rng, n_per_face, CUBE)


@dataclass
class MovingRun:
    X_true: list  # X_k, the cube in the camera at step k
    G_RC: list  # camera in robot at step k
    G_odom: list  # measured odometry increment k-1 -> k (noisy)
    dt: float


def moving_run(
    rng, n_steps=60, dt=0.2, v_obj=0.1, follow_m=1.1, tilt=-0.25, odom_noise=(0.05, 0.05, 0.02)
) -> MovingRun:
    """A cube moving at ``v_obj`` m/s (straight line, slow yaw) followed by the robot at about
    ``follow_m`` metres, the pan-tilt tracking it. Returns the true camera-frame poses X_k and the
    filter's inputs: G_RC at each step and noisy odometry increments (errors drawn from the same
    model as ``ProcessNoise``'s defaults)."""
    yaw0 = rng.uniform(-np.pi, np.pi)
    G_WO0 = se3(euler_zyx_to_R(yaw0, 0.6, 0.0), (1.2, 0.0, 0.45))  # tilted: keeps away from gimbal lock
    heading = rng.uniform(-np.pi, np.pi)
    v_W = v_obj * np.array([np.cos(heading), np.sin(heading), 0.0])
    yaw_rate = rng.uniform(-0.1, 0.1)
    robot = Pose2D(0.0, 0.0, 0.0)
    X_true, G_RCs, G_odoms = [], [], []
    for k in range(n_steps):
        t = k * dt
        G_WO = se3(euler_zyx_to_R(yaw_rate * t, 0.0, 0.0), v_W * t) @ G_WO0
        p_R = se3_inv(robot.G()) @ G_WO[:, 3]  # the object seen from the robot
        pan = float(np.arctan2(p_R[1], p_R[0]))  # the pan-tilt tracks it
        G_RC = CAMERA.G_RC(pan, tilt)
        X_true.append(G_to_pose6(se3_inv(robot.G() @ G_RC) @ G_WO))
        G_RCs.append(G_RC)
        # the robot follows: turn towards the object, keep follow_m metres
        dist = float(np.hypot(p_R[0], p_R[1]))
        v = float(np.clip(0.8 * (dist - follow_m), -0.2, 0.2))
        omega = float(np.clip(1.0 * pan, -0.5, 0.5))
        th = robot.theta + 0.5 * omega * dt
        new = Pose2D(robot.x + v * dt * np.cos(th), robot.y + v * dt * np.sin(th), robot.theta + omega * dt)
        s = abs(v) * dt
        st, sr = odom_noise[0] * s, odom_noise[1] * abs(omega * dt) + odom_noise[2] * s
        G_true = se3_inv(robot.G()) @ new.G()
        err = se3(euler_zyx_to_R(rng.normal(0, sr), 0, 0), (rng.normal(0, st), rng.normal(0, st), 0.0))
        G_odoms.append(G_true @ se3_inv(err))  # true = measured @ Exp(err): the filter's odometry model
        robot = new
    return MovingRun(X_true, G_RCs, G_odoms, dt)
