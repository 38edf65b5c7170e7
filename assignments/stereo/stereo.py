r"""Assignment 0 (warm-up): from a rectified stereo pair to 3D points, and back to pixels.

The stereo head's two cameras are rectified: same focal length ``f`` [px] and principal point
``(cx, cy)`` [px], the right camera ``baseline`` metres along the left camera's x axis. A point seen at
pixel ``(u, v)`` in the left image and ``(u - d, v)`` in the right one has disparity ``d`` [px]. Points
are in the left camera's optical frame C: x right, y down, z forward (docs/conventions.md).

Write the functions below with NumPy (no ``lab`` imports). Run the public tests with
``python -m pytest test_stereo.py``.
"""

import numpy as np


def triangulate(uv, disparity, f: float, cx: float, cy: float, baseline: float) -> np.ndarray:
    r"""3D points in C from left-image pixels and disparities.

    .. math:: Z = \frac{f\, b}{d}, \qquad X = \frac{(u - c_x) Z}{f}, \qquad Y = \frac{(v - c_y) Z}{f}

    Parameters
    ----------
    uv : array_like, shape (n, 2) [px]
        Left-image pixel coordinates ``(u, v)``.
    disparity : array_like, shape (n,) [px]
        ``u_left - u_right``.
    f, cx, cy : float [px]
    baseline : float [m]

    Returns
    -------
    points_C : ndarray, shape (n, 3) [m]
        A row of NaN where the disparity is not positive (no finite depth).
    """
    ### BEGIN SOLUTION
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    d = np.asarray(disparity, dtype=float).reshape(-1)
    out = np.full((d.size, 3), np.nan)
    ok = d > 0
    Z = f * baseline / d[ok]
    out[ok, 0] = (uv[ok, 0] - cx) * Z / f
    out[ok, 1] = (uv[ok, 1] - cy) * Z / f
    out[ok, 2] = Z
    return out
    ### END SOLUTION


def project(points_C, f: float, cx: float, cy: float) -> np.ndarray:
    r"""Pixel coordinates of 3D points in the left image: the pinhole model of Eq. (16).

    .. math:: u = \frac{f\, x}{z} + c_x, \qquad v = \frac{f\, y}{z} + c_y

    Parameters
    ----------
    points_C : array_like, shape (n, 3) [m]
    f, cx, cy : float [px]

    Returns
    -------
    uv : ndarray, shape (n, 2) [px]
        A row of NaN for points not in front of the camera (``z <= 0``).
    """
    ### BEGIN SOLUTION
    p = np.asarray(points_C, dtype=float).reshape(-1, 3)
    out = np.full((p.shape[0], 2), np.nan)
    ok = p[:, 2] > 0
    out[ok, 0] = f * p[ok, 0] / p[ok, 2] + cx
    out[ok, 1] = f * p[ok, 1] / p[ok, 2] + cy
    return out
    ### END SOLUTION


def depth_std(Z, f: float, baseline: float, sigma_disparity: float):
    r"""Standard deviation of stereo depth, to first order: it grows with the square of the distance.

    .. math:: \sigma_Z = \left\lvert \frac{\partial Z}{\partial d} \right\rvert \sigma_d
        = \frac{Z^2}{f\, b}\, \sigma_d

    Parameters
    ----------
    Z : float or array_like [m]
        Depths (> 0).
    f : float [px]
    baseline : float [m]
    sigma_disparity : float [px]

    Returns
    -------
    float or ndarray, the shape of ``Z`` [m]
    """
    ### BEGIN SOLUTION
    Z = np.asarray(Z, dtype=float)
    return Z**2 * sigma_disparity / (f * baseline)
    ### END SOLUTION
