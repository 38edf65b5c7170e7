"""The local search's "small covariance" (``lab.search.tracking.pose_stds``) given the calibration: the
share of the pose's covariance that the calibration error every frame shares explains, and the pose's
covariance given that error, the Schur complement of the joint covariance of ``[x, c]`` (checked against
the dense joint matrix's precision)."""

import numpy as np
from ekf_scenarios import cube, observe

from lab.estimation import CalibrationUncertainty, EKFConfig, GateConfig, OrientationChart, PoseEKF
from lab.search.tracking import calibration_share, pose_stds

X = np.array([0.05, -0.02, 0.8, 0.4, 0.3, -2.0])
CAL = CalibrationUncertainty(scale_std=0.01, pointing_std_deg=0.0, focal_std=0.01)  # error scale 2's


def _filter(cal, chart=OrientationChart.ROTATION_VECTOR, seed=3):
    rng = np.random.default_rng(seed)
    cfg = EKFConfig(gate=GateConfig(dist_max_m=np.inf, gate_prob=None), calibration=cal, chart=chart)
    ekf = PoseEKF(cfg, rng=rng)
    ekf.initialize(
        X + rng.normal(0, [0.01, 0.01, 0.02, 0.02, 0.02, 0.02]), np.diag([0.02] * 3 + [0.05] * 3) ** 2
    )
    return ekf, rng


def test_the_calibrations_share_is_the_schur_complement_of_the_joint_covariance():
    b_O, nrm = cube(np.random.default_rng(1))
    for chart in (OrientationChart.ROTATION_VECTOR, OrientationChart.EULER):
        ekf, rng = _filter(CAL, chart)
        for _ in range(3):
            f = observe(rng, X, b_O, nrm)
            assert ekf.update(f.d_C, f.b_O, f.Sigma_d).applied
        cols = [0, 4, 5]  # s, a_x, a_y: the columns with a nonzero sigma
        Sc = CAL.covariance()[np.ix_(cols, cols)]
        P = ekf.P
        T = np.eye(6)
        if chart is OrientationChart.EULER:
            from lab.estimation.models import euler_to_rv_jacobian

            T = euler_to_rv_jacobian(ekf.mu)
        joint = np.block([[T @ P @ T.T, T @ ekf.P_xc], [(T @ ekf.P_xc).T, Sc]])
        given_c = np.linalg.inv(
            np.linalg.inv(joint)[:6, :6]
        )  # the conditional covariance, from the precision
        np.testing.assert_allclose(ekf.Sigma_rv - calibration_share(ekf), given_c, atol=1e-12)
        assert np.linalg.eigvalsh(given_c).min() > 0


def test_the_pose_given_the_calibration_is_the_tracks_own_uncertainty():
    """At error scale 2's stated calibration (1 % on the baseline and on each focal length), a cube
    0.8 m away: the calibration's share dominates the stated position deviation, the rest shrinks with
    the frames, and a filter without a calibration error has nothing to leave out."""
    b_O, nrm = cube(np.random.default_rng(1))
    ekf, rng = _filter(CAL)
    stds = []
    for _ in range(6):
        f = observe(rng, X, b_O, nrm)
        assert ekf.update(f.d_C, f.b_O, f.Sigma_d).applied
        stds.append((pose_stds(ekf)[0], pose_stds(ekf, calibration=False)[0]))
    assert all(given < 0.85 * full for full, given in stds)
    assert stds[-1][1] < 0.95 * stds[0][1]
    plain, rng = _filter(CalibrationUncertainty.none())
    f = observe(rng, X, b_O, nrm)
    assert plain.update(f.d_C, f.b_O, f.Sigma_d).applied
    assert pose_stds(plain) == pose_stds(plain, calibration=False)
    assert not calibration_share(plain).any()
