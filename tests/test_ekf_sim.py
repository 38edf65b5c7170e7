"""The pose EKF on rendered frames: real stereo SIFT features matched against trained databases.

Ground truth comes from the simulator (the carried box's true pose and the true camera pose). Views
show the box's unique face: with three identical faces, a view of shared faces alone is ambiguous by
a 90 degree turn (it looks the same), so no filter can recover the pose from it.
"""

import math

import numpy as np
import pytest

from lab.estimation import EKFConfig, OrientationChart, PoseEKF, nees
from lab.geometry import G_to_pose6, Pose2D, relative_pose2d, se3_inv
from lab.sim import OdometryNoise, SimRobot, SimWorld, load_box_models
from lab.training import get_database
from lab.vision import Matcher, stereo_features


def _errors(estimate, G_CO_true):
    t_err = float(np.linalg.norm(estimate.mu[:3] - G_CO_true[:3, 3]))
    R_err = estimate.G_CO[:3, :3].T @ G_CO_true[:3, :3]
    return t_err, math.degrees(math.acos(np.clip((np.trace(R_err) - 1) / 2, -1, 1)))


def _aim(robot, G_WO):
    """Pan and tilt that point the camera at the box centre (from the true pose: test set-up only)."""
    p = robot.world.truth.robot_pose()
    c = G_WO[:3, 3]
    pan = math.atan2(c[1] - p.y, c[0] - p.x) - p.theta
    tilt = math.atan2(c[2] - robot.camera.mount_R[2], math.hypot(c[0] - p.x, c[1] - p.y))
    return math.atan2(math.sin(pan), math.cos(pan)), tilt


@pytest.fixture(scope="module")
def databases():
    models = load_box_models()
    return models, {m.name: get_database(m.name, progress=False) for m in models}


def test_static_box_converges_from_ransac(databases):
    models, dbs = databases
    t_errs, r_errs = [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        m = models[seed % 4]
        dist = rng.uniform(0.8, 1.5)
        with SimWorld("box_database") as w:
            # the robot looks along +x at the box; the unique face (+X of the box) turned towards it +-35 deg
            box_yaw = math.pi + rng.uniform(-0.6, 0.6)
            carrier = w.add_carrier(m, Pose2D(0.0, 0.0, 0.0), box_yaw=box_yaw)
            robot = SimRobot(
                w, start=Pose2D(-dist, rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2)), seed=seed
            )
            robot.enable()
            robot.command_pan_tilt(*_aim(robot, carrier.G_WO))
            robot.wait_pan_tilt()
            ekf = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(seed))
            matcher = Matcher(dbs[m.name])
            G_RC = robot.camera.G_RC(robot.pan_tilt().pan, robot.pan_tilt().tilt)
            for _ in range(20):
                frame = robot.capture_stereo()
                f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t)
                ekf.predict(G_RC, G_RC, np.eye(4), 0.1)
                ekf.update(*matcher.match(f).pairs(f, dbs[m.name]))
                robot.step(0.1)
            assert ekf.initialized, (seed, ekf.last_result)
            G_CO = se3_inv(w.truth.G_WC()) @ carrier.G_WO
            t, r = _errors(ekf.estimate, G_CO)
            t_errs.append(t)
            r_errs.append(r)
    print(
        f"\nstatic, 10 placements at 0.8-1.5 m: translation median {np.median(t_errs) * 100:.2f} cm "
        f"(max {max(t_errs) * 100:.2f}), rotation median {np.median(r_errs):.2f} deg (max {max(r_errs):.2f})"
    )
    assert np.median(t_errs) <= 0.01
    assert np.median(r_errs) <= 2.0


def test_moving_box_robot_driving_and_head_tracking(databases):
    """The box rides a carrier at 0.1 m/s, the robot drives and pans to follow the estimate (not the
    truth): errors while the object is in view, and NEES against its chi-square(6) 95% band."""
    from scipy.stats import chi2

    models, dbs = databases
    m = models[2]
    lo, hi = chi2.ppf(0.025, 6), chi2.ppf(0.975, 6)
    dt = 0.1
    with SimWorld("arena") as w:
        # carrier drives along +y; its box shows the unique face (+X) towards the robot on its -x side
        carrier = w.add_carrier(m, Pose2D(0.0, -0.6, math.pi / 2), box_yaw=math.pi / 2)
        carrier.set_velocity(0.1, 0.0)
        robot = SimRobot(w, start=Pose2D(-1.2, -0.9, math.pi / 2), seed=7, odometry_noise=OdometryNoise())
        robot.enable()
        robot.command_pan_tilt(*_aim(robot, carrier.G_WO))  # set-up only; afterwards it tracks the estimate
        robot.wait_pan_tilt()
        ekf = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(7))
        matcher = Matcher(dbs[m.name])
        prev = None
        t_errs, r_errs, in_band = [], [], []
        for k in range(100):
            frame = robot.capture_stereo()
            G_WC_true = w.truth.G_WC()
            G_WO_true = carrier.G_WO
            if prev is not None:
                ekf.predict(prev.G_RC, frame.G_RC, relative_pose2d(prev.odom, frame.odom), frame.t - prev.t)
            prev = frame
            f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t)
            res = ekf.update(*matcher.match(f).pairs(f, dbs[m.name]))
            if res.applied and k >= 5:  # after a few frames to converge from the RANSAC start
                G_CO = se3_inv(G_WC_true) @ G_WO_true
                t, r = _errors(ekf.estimate, G_CO)
                t_errs.append(t)
                r_errs.append(r)
                e = nees(G_to_pose6(G_CO), ekf.estimate, OrientationChart.ROTATION_VECTOR)
                in_band.append(lo <= e <= hi)
            if ekf.initialized:  # pan and tilt towards the estimated object centre (a proportional step)
                p_R = frame.G_RC @ np.append(ekf.estimate.mu[:3], 1.0)
                pan = math.atan2(p_R[1], p_R[0])
                tilt = math.atan2(p_R[2] - robot.camera.mount_R[2], math.hypot(p_R[0], p_R[1]))
                robot.command_pan_tilt(pan, tilt)
            robot.drive(0.06, 0.0)
            robot.step(dt)
        assert w.truth.collisions == 0
    print(
        f"\nmoving: {len(t_errs)} updated frames of 95; translation median {np.median(t_errs) * 100:.2f} cm "
        f"(p90 {np.percentile(t_errs, 90) * 100:.2f}), rotation median {np.median(r_errs):.2f} deg "
        f"(p90 {np.percentile(r_errs, 90):.2f}); NEES inside its 95% band on {np.mean(in_band):.0%} of frames"
    )
    assert len(t_errs) >= 70  # the object stayed in view and tracked
    assert np.median(t_errs) <= 0.03
    assert np.median(r_errs) <= 5.0
    assert np.mean(in_band) >= 0.6
