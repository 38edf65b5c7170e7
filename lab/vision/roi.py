r"""Regions of interest: where in a stereo pair a tracked object's features can be.

Both papers restrict SIFT to a region of interest once an object is tracked (the search paper: "limited
to a region of interest ... once the object track has been initialized"). The region is the object's
bounding box projected into the left image at the predicted pose ``G_CO``:

* :func:`object_roi`: the box at one pose, grown by a fixed margin in pixels (the search's refinement);
* :func:`tracked_roi`: the union over several poses (a filter bank's predictions and their look-alike
  turns), each corner ``p = R b + t`` of each box widened by ``n_sigma`` standard deviations of its
  pixel position and depth. Under the pose covariance ``Sigma_rv`` over ``[x, phi]`` (the
  rotation-vector chart) a corner's covariance in C is the scoring's ``C Sigma_rv C^T`` with
  ``C = [I, -[R b]_x]``, and its pixel covariance follows through the projection's Jacobian,

  .. math:: \Sigma_{uv} = J \, C \Sigma_{rv} C^T J^T, \qquad
            J = \begin{bmatrix} f_x / Z & 0 & -f_x X / Z^2 \\ 0 & f_y / Z & -f_y Y / Z^2 \end{bmatrix}.

  The corners' depths ``Z -+ n_sigma sigma_Z`` give the disparities ``d = f_x B / Z`` the region's
  features can have, which bound the band of the right image that can hold their partners
  (:meth:`RegionOfInterest.right_band`).

A region that would cover most of the image (``max_fraction``) is no region: the caller extracts the
full frame, as it does when the track is lost.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.geometry import transform_points
from lab.robot import StereoCamera

__all__ = ["RegionOfInterest", "box_corners", "object_roi", "tracked_roi"]

#: Nearest depth [m] at which a box corner still counts as in front of the camera.
_MIN_DEPTH_M = 0.05


@dataclass(frozen=True)
class RegionOfInterest:
    """A rectangle of the left image and the disparities of the features it can hold.

    Attributes
    ----------
    x, y, w, h : int [px]
        The rectangle: columns ``x .. x + w - 1``, rows ``y .. y + h - 1`` (inside the image).
    min_disparity, max_disparity : float [px]
        The disparities ``u_L - u_R`` its features can have (the stereo matcher's whole range when the
        depths are unknown).
    """

    x: int
    y: int
    w: int
    h: int
    min_disparity: float
    max_disparity: float

    def __post_init__(self):
        if self.w <= 0 or self.h <= 0 or self.x < 0 or self.y < 0:
            raise ConfigError(f"a region needs x, y >= 0 and w, h > 0 px, got {self.rect}")
        if not 0 <= self.min_disparity <= self.max_disparity:
            raise ConfigError(
                f"need 0 <= min_disparity <= max_disparity, got {self.min_disparity}, {self.max_disparity}"
            )

    @property
    def rect(self) -> tuple[int, int, int, int]:
        """``(x, y, w, h)`` [px]."""
        return self.x, self.y, self.w, self.h

    @property
    def area(self) -> int:
        """[px^2]"""
        return self.w * self.h

    def contains(self, uv: np.ndarray) -> np.ndarray:
        """Which pixels ``uv`` (n, 2) [px] lie inside the rectangle, (n,) bool."""
        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        u, v = uv[:, 0], uv[:, 1]
        return (u >= self.x) & (u < self.x + self.w) & (v >= self.y) & (v < self.y + self.h)

    def right_band(self, camera: StereoCamera, max_dy: float) -> RegionOfInterest | None:
        """The rectangle of the right image that can hold the partners of the region's features.

        A rectified pair puts a feature's partner on its row (within ``max_dy`` [px]) at
        ``u_R = u_L - d``, with ``d`` within ``[min_disparity, max_disparity]``: rows ``y - max_dy ..
        y + h + max_dy``, columns ``x - max_disparity .. x + w - min_disparity`` (1 px more each side
        for the rounding), clipped to the image. None when that is empty.
        """
        x0 = max(0, int(np.floor(self.x - self.max_disparity)) - 1)
        x1 = min(camera.width, int(np.ceil(self.x + self.w - self.min_disparity)) + 1)
        y0 = max(0, int(np.floor(self.y - max_dy)) - 1)
        y1 = min(camera.height, int(np.ceil(self.y + self.h + max_dy)) + 1)
        if x1 <= x0 or y1 <= y0:
            return None
        return RegionOfInterest(x0, y0, x1 - x0, y1 - y0, self.min_disparity, self.max_disparity)


def box_corners(extent) -> np.ndarray:
    """The 8 corners (8, 3) [m] of a box of size ``extent`` (x, y, z) [m] centred on its frame's origin."""
    h = 0.5 * np.asarray(extent, dtype=float)
    return np.array([[sx * h[0], sy * h[1], sz * h[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def object_roi(
    G_CO: np.ndarray, extent, camera: StereoCamera, margin_px: int
) -> tuple[int, int, int, int] | None:
    """The region of interest ``(x, y, w, h)`` [px] around the object's box projected at pose ``G_CO``.

    None when the object is (partly) behind the camera or the box falls outside the image.
    """
    p = transform_points(G_CO, box_corners(extent))
    if np.any(p[:, 2] <= _MIN_DEPTH_M):
        return None
    return _rect(camera.project(p), camera, margin_px)


def _rect(uv: np.ndarray, camera: StereoCamera, margin_px: float) -> tuple[int, int, int, int] | None:
    """The pixels' bounding rectangle grown by ``margin_px`` and clipped to the image; None when less
    than 8 px remain either way."""
    x0, y0 = np.floor(uv.min(axis=0)) - margin_px
    x1, y1 = np.ceil(uv.max(axis=0)) + margin_px
    x0, y0 = max(0, int(x0)), max(0, int(y0))
    x1, y1 = min(camera.width, int(x1)), min(camera.height, int(y1))
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    return x0, y0, x1 - x0, y1 - y0


def _corner_spread(G_CO: np.ndarray, Sigma_rv: np.ndarray, extent, camera: StereoCamera):
    """The box's corners projected at each of P poses ``G_CO`` (P, 4, 4): pixels ``uv`` (P, 8, 2) [px],
    depths ``Z`` (P, 8) [m], and the standard deviations of ``u``, ``v`` (P, 8, 2) [px] and of ``Z``
    (P, 8) [m] that the covariances ``Sigma_rv`` (P, 6, 6) give them (module docstring)."""
    R, t = G_CO[:, :3, :3], G_CO[:, :3, 3]
    q = box_corners(extent)[None] @ np.swapaxes(R, 1, 2)  # R b, (P, 8, 3)
    p = q + t[:, None, :]
    X, Y, Z = p[..., 0], p[..., 1], p[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([camera.fx * X / Z + camera.cx, camera.fy * Y / Z + camera.cy], axis=-1)
    C = np.zeros(q.shape[:2] + (3, 6))  # d p / d [x, phi] = [I, -[q]_x]
    C[..., :, :3] = np.eye(3)
    C[..., 0, 4], C[..., 0, 5] = q[..., 2], -q[..., 1]
    C[..., 1, 3], C[..., 1, 5] = -q[..., 2], q[..., 0]
    C[..., 2, 3], C[..., 2, 4] = q[..., 1], -q[..., 0]
    S_p = C @ Sigma_rv[:, None] @ np.swapaxes(C, -1, -2)  # (P, 8, 3, 3)
    J = np.zeros(q.shape[:2] + (2, 3))  # d (u, v) / d p
    with np.errstate(divide="ignore", invalid="ignore"):
        J[..., 0, 0], J[..., 0, 2] = camera.fx / Z, -camera.fx * X / Z**2
        J[..., 1, 1], J[..., 1, 2] = camera.fy / Z, -camera.fy * Y / Z**2
    S_uv = J @ S_p @ np.swapaxes(J, -1, -2)
    sd_uv = np.sqrt(np.maximum(np.stack([S_uv[..., 0, 0], S_uv[..., 1, 1]], axis=-1), 0.0))
    return uv, Z, sd_uv, np.sqrt(np.maximum(S_p[..., 2, 2], 0.0))


def tracked_roi(
    poses: Sequence[tuple[np.ndarray, np.ndarray | None]],
    extent,
    camera: StereoCamera,
    min_disparity: float,
    max_disparity: float,
    margin_px: float = 8.0,
    n_sigma: float = 3.0,
    max_fraction: float = 0.6,
    disparity_margin_px: float = 2.0,
) -> RegionOfInterest | None:
    """The region of the left image that holds the object's box at every one of ``poses``.

    Parameters
    ----------
    poses : sequence of (ndarray (4, 4), ndarray (6, 6) or None)
        ``(G_CO, Sigma_rv)``: the object in the camera frame C and the covariance of ``[x, phi]``
        [m, rad] (the rotation-vector chart); each corner is widened by ``n_sigma`` standard deviations
        of its pixel position and depth (module docstring). A pose that can put a corner behind the
        camera makes the region unknown (None); one whose box falls wholly outside the image adds
        nothing.
    extent : array_like, shape (3,) [m]
        The box's size along O's axes.
    camera : StereoCamera
    min_disparity, max_disparity : float [px]
        The stereo matcher's disparity range: the region's range is the grown boxes' clipped to it.
    margin_px : float [px]
        Added around the projected boxes (a keypoint's support reaches beyond its centre).
    n_sigma : float
        Standard deviations the corners are widened by.
    max_fraction : float
        A region larger than this fraction of the image is no region (None: the full frame).
    disparity_margin_px : float [px]
        Added to each end of the corners' disparity range (the disparity's own noise).

    Returns
    -------
    RegionOfInterest or None
        None: extract the full frame (no pose, a box behind the camera, none in the image, or a region
        covering more than ``max_fraction`` of the image).
    """
    if not 0 < max_fraction <= 1:
        raise ConfigError(f"max_fraction must be within (0, 1], got {max_fraction}")
    if not len(poses):
        return None
    G = np.stack([np.asarray(g, dtype=float) for g, _ in poses])
    Sigma = np.stack([np.zeros((6, 6)) if S is None else np.asarray(S, dtype=float) for _, S in poses])
    uv, Z, sd_uv, sd_Z = _corner_spread(G, Sigma, extent, camera)  # all poses' corners at once
    z_near, z_far = Z - n_sigma * sd_Z, Z + n_sigma * sd_Z
    if np.any(z_near <= _MIN_DEPTH_M):
        return None
    lo, hi = uv - n_sigma * sd_uv, uv + n_sigma * sd_uv  # (P, 8, 2)
    W, H = camera.width, camera.height
    u0, v0 = lo[..., 0].min(axis=1) - margin_px, lo[..., 1].min(axis=1) - margin_px
    u1, v1 = hi[..., 0].max(axis=1) + margin_px, hi[..., 1].max(axis=1) + margin_px
    seen = (np.minimum(u1, W) - np.maximum(u0, 0) >= 8) & (np.minimum(v1, H) - np.maximum(v0, 0) >= 8)
    if not seen.any():  # every box wholly outside the image
        return None
    rect = _rect(np.concatenate([lo[seen].reshape(-1, 2), hi[seen].reshape(-1, 2)]), camera, margin_px)
    if rect is None or rect[2] * rect[3] > max_fraction * camera.width * camera.height:
        return None
    fB = camera.fx * camera.baseline
    d_lo = max(min_disparity, fB / z_far[seen].max() - disparity_margin_px)
    d_hi = min(max_disparity, fB / z_near[seen].min() + disparity_margin_px)
    if d_lo > d_hi:  # the boxes lie outside the stereo range: their features cannot be matched
        return None
    return RegionOfInterest(*rect, d_lo, d_hi)
