"""Graded tests of assignment 0 (stereo warm-up). Never released to students.

References: OpenCV's ``triangulatePoints`` (DLT from the two projection matrices) and ``projectPoints``,
and a seeded Monte Carlo estimate of the depth spread.
"""

import cv2
import numpy as np

from lab.grading.suite import TestSuite, as_array, check_close, fail, fmt

suite = TestSuite("stereo")

F, CX, CY, B = 207.8, 159.5, 119.5, 0.12


def _scene(rng, n=25):
    p = np.column_stack([rng.uniform(-1.0, 1.0, n), rng.uniform(-0.6, 0.6, n), rng.uniform(0.5, 6.0, n)])
    K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    P_left = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P_right = K @ np.hstack([np.eye(3), [[-B], [0], [0]]])  # the right camera at +B along x
    uv_l = (P_left @ np.vstack([p.T, np.ones(n)])).T
    uv_r = (P_right @ np.vstack([p.T, np.ones(n)])).T
    uv_l, uv_r = uv_l[:, :2] / uv_l[:, 2:], uv_r[:, :2] / uv_r[:, 2:]
    return p, P_left, P_right, uv_l, uv_r


@suite.test(
    "triangulate agrees with OpenCV's triangulatePoints on 25 seeded points",
    points=2,
    target="triangulate",
    visibility="visible",
)
def triangulate_matches_opencv(sub):
    rng = np.random.default_rng(1)
    _, P_left, P_right, uv_l, uv_r = _scene(rng)
    uv_l = uv_l + rng.normal(0, 0.2, uv_l.shape)  # measured pixels: not exactly consistent
    uv_r[:, 1] = uv_l[:, 1]  # rectified: same row
    X = cv2.triangulatePoints(P_left, P_right, uv_l.T.copy(), uv_r.T.copy())
    want = (X[:3] / X[3]).T
    got = as_array(
        sub.triangulate(uv_l, uv_l[:, 0] - uv_r[:, 0], F, CX, CY, B),
        "triangulate(uv, disparity, ...)",
        (25, 3),
    )
    if np.allclose(got[:, :2], -want[:, :2], rtol=1e-6):
        fail("triangulate has x and y with the wrong sign: x = (u - cx) Z / f, y = (v - cy) Z / f")
    check_close(got, want, "triangulate(uv, disparity, f, cx, cy, baseline)", rtol=1e-6, atol=1e-9)


@suite.test(
    "triangulate returns NaN rows where the disparity is 0 or negative", points=1, target="triangulate"
)
def triangulate_invalid_disparity(sub):
    uv = np.array([[10.0, 20.0], [100.0, 120.0], [200.0, 30.0], [CX, CY]])
    d = np.array([0.0, -3.0, 8.0, 25.0])
    got = as_array(
        sub.triangulate(uv, d, F, CX, CY, B),
        "triangulate with disparities [0, -3, 8, 25]",
        (4, 3),
        finite=False,
    )
    if not np.all(np.isnan(got[:2])):
        fail(
            f"triangulate with disparity 0 and -3 returned {fmt(got[:2])}; expected rows of NaN (no finite "
            "depth)"
        )
    if not np.all(np.isfinite(got[2:])):
        fail(f"triangulate with disparities 8 and 25 returned {fmt(got[2:])}; expected finite points")
    _, P_left, P_right, _, _ = _scene(np.random.default_rng(0), n=1)
    right = uv[2:] - np.column_stack([d[2:], np.zeros(2)])  # the same points in the right image
    X = cv2.triangulatePoints(P_left, P_right, uv[2:].T.copy(), right.T.copy())
    check_close(
        got[2:],
        (X[:3] / X[3]).T,
        "triangulate with disparities 8 and 25 (the valid rows, against OpenCV)",
        rtol=1e-6,
        atol=1e-9,
    )


@suite.test(
    "project agrees with OpenCV's projectPoints (Eq. (16)) and NaN behind the camera",
    points=1,
    target="project",
)
def project_matches_opencv(sub):
    rng = np.random.default_rng(2)
    p, *_ = _scene(rng)
    K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    want, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, None)
    got = as_array(sub.project(p, F, CX, CY), "project(points_C, f, cx, cy)", (25, 2))
    check_close(got, want.reshape(-1, 2), "project(points_C, f, cx, cy)", rtol=1e-9, atol=1e-9)
    behind = as_array(
        sub.project(np.array([[0.1, 0.2, -1.0], [0.0, 0.0, 0.0]]), F, CX, CY),
        "project of points with z <= 0",
        (2, 2),
        finite=False,
    )
    if not np.all(np.isnan(behind)):
        fail(f"project of points with z = -1 and z = 0 returned {fmt(behind)}; expected NaN rows")


@suite.test(
    "project(triangulate(uv, d)) gives back uv in the left camera and (u - d, v) in the right one, and "
    "triangulate(project(p), f b / z) gives back p",
    points=1,
    target="project",
    uses=("triangulate",),
)
def round_trip(sub):
    """The two ways must undo each other, and each is also checked against values known here: a wrong
    pair can undo itself (triangulate keeping the pixels, project dropping the depth), and a pair can
    remember what it was asked within one test."""
    rng = np.random.default_rng(3)
    uv = rng.uniform([0, 0], [320, 240], (30, 2))
    d = rng.uniform(2, 60, 30)
    p = as_array(sub.triangulate(uv, d, F, CX, CY, B), "triangulate", (30, 3))
    back = as_array(sub.project(p, F, CX, CY), "project", (30, 2))
    check_close(back, uv, "project(triangulate(uv, d))", atol=1e-9, rtol=1e-12)
    points, *_ = _scene(rng, n=30)  # points at known positions: the way back must find them again
    seen = as_array(sub.project(points, F, CX, CY), "project", (30, 2))
    again = as_array(sub.triangulate(seen, F * B / points[:, 2], F, CX, CY, B), "triangulate", (30, 3))
    check_close(
        again,
        points,
        "triangulate(project(p), f b / z)",
        rtol=1e-9,
        atol=1e-9,
        hint="The two must be inverses for points in front of the camera, depth included.",
    )
    # undoing each other is not enough: the values themselves
    check_close(
        p[:, 2],
        F * B / d,
        "the depth column of triangulate(uv, d)",
        rtol=1e-9,
        atol=1e-9,
        hint="Z = f b / d: the depth of a point whose disparity is d.",
    )
    right = as_array(sub.project(p - [B, 0.0, 0.0], F, CX, CY), "project", (30, 2))
    check_close(
        right,
        uv - np.column_stack([d, np.zeros(30)]),
        "project(triangulate(uv, d) - [b, 0, 0]), the points as the right camera sees them",
        atol=1e-9,
        rtol=1e-12,
        hint="The right camera sits b along x: it sees each point at (u - d, v), d being the disparity.",
    )
    K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    want, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, None)
    check_close(
        seen, want.reshape(-1, 2), "project(p) (against OpenCV's projectPoints)", rtol=1e-9, atol=1e-9
    )


@suite.test(
    "depth_std matches Z^2 sigma_d / (f b) and a seeded Monte Carlo spread", points=1, target="depth_std"
)
def depth_std_monte_carlo(sub):
    rng = np.random.default_rng(4)
    Z = np.array([0.5, 1.0, 2.0, 4.0])
    sigma_d = 0.25
    got = as_array(sub.depth_std(Z, F, B, sigma_d), "depth_std(Z, f, baseline, sigma_disparity)", (4,))
    check_close(got, Z**2 * sigma_d / (F * B), "depth_std", rtol=1e-9)
    d = F * B / Z[:, None] + rng.normal(0, sigma_d, (4, 20000))
    mc = (F * B / d).std(axis=1)
    if not np.allclose(got, mc, rtol=0.05):
        fail(f"depth_std = {fmt(got)} differs from the Monte Carlo spread {fmt(mc)} by more than 5 %")
