"""Notebook 00's checks: the pinhole projection, triangulation and depth uncertainty (assignment ``stereo``).

See :mod:`lab.exercises` for what a check does and how it avoids carrying the answer.
"""

from __future__ import annotations

import numpy as np

from lab.exercises.feedback import Feedback, Mistake, answer_array, call_answer, checked, close, verdict

__all__ = ["check_triangulate", "check_project", "check_depth_std"]

_F, _CX, _CY, _B = 207.8, 159.5, 119.5, 0.12  # the simulated head: 320 x 240, 60 deg vertical field of view


def _stereo_inputs():
    rng = np.random.default_rng(51)
    uv = np.column_stack([rng.uniform(20, 300, 6), rng.uniform(20, 220, 6)])
    disparity = rng.uniform(5.0, 40.0, 6)
    return uv, disparity


def _cv_triangulate(uv, disparity, f, cx, cy, baseline):
    import cv2

    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    P_L = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P_R = K @ np.hstack([np.eye(3), [[-baseline], [0.0], [0.0]]])
    uv_R = uv - np.column_stack([disparity, np.zeros_like(disparity)])
    X = cv2.triangulatePoints(P_L, P_R, uv.T.astype(float), uv_R.T.astype(float))
    return (X[:3] / X[3]).T


@checked
def check_triangulate(triangulate) -> Feedback:
    """Check ``triangulate(uv, disparity, f, cx, cy, baseline) -> points_C`` (n, 3) [m] against OpenCV's
    ``triangulatePoints`` on the rectified pair (the right pixel ``u - d`` on the same row)."""
    name = "triangulate"
    uv, d = _stereo_inputs()
    got = answer_array(
        name, call_answer(name, triangulate, uv.copy(), d.copy(), _F, _CX, _CY, _B), (len(d), 3)
    )
    want = _cv_triangulate(uv, d, _F, _CX, _CY, _B)
    Z = want[:, 2]
    mistakes = [
        Mistake(
            "units", "the right shape, but 1000 times too large: millimetres? Work in metres", want * 1000
        ),
        Mistake(
            "depth_inverted",
            "your depth grows with the disparity: a near point has a LARGE disparity, Z = f B / d",
            test=lambda g: close(g[:, 2] / d, np.full(len(d), g[0, 2] / d[0]), 1e-6),
        ),
        Mistake(
            "principal_point",
            "X and Y are off by a constant in pixels: measure u and v from the principal point (cx, cy)",
            np.column_stack([uv[:, 0] * Z / _F, uv[:, 1] * Z / _F, Z]),
        ),
        Mistake(
            "swapped_axes", "X and Y are swapped: X goes with u (right), Y with v (down)", want[:, [1, 0, 2]]
        ),
        Mistake(
            "sign",
            "a wrong sign: in the camera frame x points right, y down and z forward",
            test=lambda g: close(np.abs(g), np.abs(want), 1e-6),
        ),
    ]
    return verdict(name, got, want, 1e-6, mistakes, "not the triangulated points: check Z = f B / d first")


@checked
def check_project(project) -> Feedback:
    """Check ``project(points_C, f, cx, cy) -> uv`` (n, 2) [px] against OpenCV's ``projectPoints``."""

    name = "project"
    uv, d = _stereo_inputs()
    p = _cv_triangulate(uv, d, _F, _CX, _CY, _B) + [0.05, -0.03, 0.2]
    got = answer_array(name, call_answer(name, project, p.copy(), _F, _CX, _CY), (len(p), 2))
    import cv2  # after the answer ran: a stub costs nothing

    K = np.array([[_F, 0, _CX], [0, _F, _CY], [0, 0, 1.0]])
    want = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, None)[0].reshape(-1, 2)
    mistakes = [
        Mistake(
            "swapped_axes", "u and v are swapped: u is the column (from X), v the row (from Y)", want[:, ::-1]
        ),
        Mistake(
            "normalisation",
            "missing normalisation: divide X and Y by the depth Z before scaling by f",
            np.column_stack([_F * p[:, 0] + _CX, _F * p[:, 1] + _CY]),
        ),
        Mistake(
            "principal_point",
            "off by a constant: add the principal point (cx, cy), it "
            "is where the optical axis meets the image",
            want - [_CX, _CY],
        ),
        Mistake("sign", "a wrong sign: subtract nothing, u = f X / Z + cx", want - 2 * np.array([_CX, _CY])),
    ]
    return verdict(
        name, got, want, 1e-6, mistakes, "not the pinhole projection u = f X / Z + cx, v = f Y / Z + cy"
    )


@checked
def check_depth_std(depth_std) -> Feedback:
    """Check ``depth_std(Z, f, baseline, sigma_disparity) -> sigma_Z`` [m], the first-order depth
    uncertainty, against a finite-difference derivative of ``Z(d) = f B / d`` times ``sigma_d``."""
    name = "depth_std"
    Zs, sigma_d = np.array([0.5, 1.0, 2.0, 3.5]), 0.4
    got = answer_array(
        name, [call_answer(name, depth_std, float(z), _F, _B, sigma_d) for z in Zs], (len(Zs),)
    )
    depth = lambda disp: _F * _B / disp  # noqa: E731
    d, h = _F * _B / Zs, 1e-6
    want = np.abs((depth(d + h) - depth(d - h)) / (2 * h)) * sigma_d
    mistakes = [
        Mistake(
            "linear",
            "your uncertainty grows linearly with the distance: it grows with its SQUARE (Z = f B / d)",
            test=lambda g: close(g / want * Zs, np.full(len(Zs), g[0] / want[0] * Zs[0]), 1e-6),
        ),
        Mistake("variance", "that is the variance: a standard deviation is its square root", want**2),
        Mistake("missing_sigma", "scale by the disparity's standard deviation sigma_d", want / sigma_d),
    ]
    return verdict(name, got, want, 1e-6, mistakes, "not the first-order sigma_Z: differentiate Z = f B / d")
