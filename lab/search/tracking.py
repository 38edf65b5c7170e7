"""The local search's tracking (the search paper's Sec. III-C): a RANSAC start refined over a few frames
with ROI-restricted SIFT, judged "found" or not (see :mod:`lab.search.local_search`), and how the head
aims at a point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from lab.estimation import PoseEKF, PoseEstimate
from lab.geometry import transform_points
from lab.robot import StereoCamera, StereoFrame, frame_motion
from lab.search.pose_check import check_pose, rest_tilt_deg
from lab.vision.roi import object_roi
from lab.vision.stereo import stereo_features, upsampled_pair

if TYPE_CHECKING:
    from lab.search.local_search import LocalSearchConfig

__all__ = ["Track", "aim_at", "pose_stds", "refine_track", "region_features"]


def aim_at(p_R: np.ndarray, camera: StereoCamera, limits=None) -> tuple[float, float]:
    """Pan and tilt [rad] that point the head at the point ``p_R`` (robot frame), clamped to ``limits``."""
    m = camera.mount_R
    dx, dy, dz = p_R[0] - m[0], p_R[1] - m[1], p_R[2] - m[2]
    pan, tilt = math.atan2(dy, dx), math.atan2(dz, math.hypot(dx, dy))
    if limits is not None:
        pan = min(max(pan, limits.pan_min), limits.pan_max)
        tilt = min(max(tilt, limits.tilt_min), limits.tilt_max)
    return pan, tilt


def pose_stds(ekf: PoseEKF) -> tuple[float, float]:
    """The largest position [m] and rotation [deg] standard deviations of the object's pose, the
    database's own error included."""
    S = ekf.object_estimate.Sigma_rv  # with the database's own error: where the object is
    pos = math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[:3, :3])[-1])))
    rot = math.degrees(math.sqrt(max(0.0, float(np.linalg.eigvalsh(S[3:, 3:])[-1]))))
    return pos, rot


def region_features(frame: StereoFrame, roi, upsample: int, detector):
    """The frame's stereo features inside ``roi`` (x, y, w, h) [px], of the pair enlarged ``upsample``
    times (:func:`lab.vision.stereo.upsampled_pair`; 1: as captured); also the camera model and region
    in the pixels of the features (``f.uv``)."""
    left, right, camera, params = upsampled_pair(frame.left, frame.right, frame.camera, upsample)
    if roi is not None and upsample > 1:
        roi = tuple(int(v) * upsample for v in roi)
    f = stereo_features(left, right, camera, params, roi=roi, t=frame.t, detector=detector)
    return f, camera, roi


def refine_track(
    robot, db, matcher, detector, ekf: PoseEKF, frame: StereoFrame, cfg: LocalSearchConfig, upsample: int = 1
):
    """Centre the object and track it over ``cfg.refine_frames`` frames with ROI-restricted SIFT, and on
    up to ``cfg.max_refine_frames`` while it is confirmed but not yet certain enough (on
    the region enlarged ``upsample`` times for a second look, and at least ``cfg.refine_upsample``
    times).

    The head aims at the estimated object centre before each frame, offset by a small dither
    (``cfg.dither_deg``, alternating directions): a simulated camera that has not moved renders the very
    same image again, which would add no information while the filter counted it as new (on the robot,
    sensor noise makes successive frames differ).
    """
    upsample = max(upsample, cfg.refine_upsample)
    prev = frame
    confirmed, last_used = 0, 0
    dither = math.radians(cfg.dither_deg)
    offsets = [(0.0, 0.0), (dither, 0.0), (-dither, dither), (0.0, -dither), (dither, dither)]
    for k in range(cfg.max_refine_frames):
        if k >= cfg.refine_frames and not _worth_another(ekf, confirmed, cfg):
            break
        p_R = transform_points(prev.G_RC, ekf.estimate.mu[:3])  # estimated object centre in R
        pan, tilt = aim_at(p_R, robot.camera)
        dp, dt = offsets[k % len(offsets)]
        lim = robot.pan_tilt_limits
        robot.command_pan_tilt(
            min(max(pan + dp, lim.pan_min), lim.pan_max), min(max(tilt + dt, lim.tilt_min), lim.tilt_max)
        )
        robot.wait_pan_tilt()
        cur = robot.capture_stereo()
        ekf.predict(prev.G_RC, cur.G_RC, frame_motion(prev, cur), max(0.0, cur.t - prev.t))
        roi = object_roi(ekf.estimate.G_CO, db.extent, cur.camera, cfg.roi_margin_px)
        f, camera, roi = region_features(cur, roi, upsample, detector)
        corr = matcher.match(f)
        res = ekf.update(*corr.pairs(f, db))  # gated by the geometric feasibility check
        last_used = res.n_used if res.applied else 0
        if res.applied and res.n_used >= cfg.confirm_matches:
            confirmed += 1
        prev = cur
    pos_std, rot_std = pose_stds(ekf)
    G_WO = prev.odom.G() @ prev.G_RC @ ekf.estimate.G_CO
    base = {
        "estimate": ekf.object_estimate,
        "frame": prev,
        "n_inliers": last_used,
        "position_std_m": pos_std,
        "rotation_std_deg": rot_std,
        "G_WO": G_WO,
    }
    if ekf.divergence is not None:
        return Track(False, f"track diverged: {ekf.divergence}", **base)
    if confirmed < cfg.confirm_updates:
        return Track(
            False,
            f"not confirmed: {confirmed} of {cfg.refine_frames} refinement updates had >= "
            f"{cfg.confirm_matches} matches (need {cfg.confirm_updates})",
            **base,
        )
    if pos_std > cfg.max_position_std_m or rot_std > cfg.max_rotation_std_deg:
        return Track(False, f"pose too uncertain: std {pos_std * 100:.1f} cm, {rot_std:.1f} deg", **base)
    tilt = rest_tilt_deg(G_WO[:3, :3])
    if cfg.max_rest_tilt_deg is not None and tilt > cfg.max_rest_tilt_deg:
        return Track(
            False,
            f"pose not confirmed: tilted {tilt:.0f} deg from resting on a face "
            f"(at most {cfg.max_rest_tilt_deg:g})",
            **base,
        )
    check = ""
    if cfg.pose_check is not None:  # does the pose explain the last frame? (lab.search.pose_check)
        pc = check_pose(f, corr, db, ekf.estimate.G_CO, camera, cfg.pose_check, roi)
        if not pc.confirmed:
            return Track(False, f"pose not confirmed: {pc.reason}", **base)
        check = f"; {pc.reason}"
    return Track(
        True,
        f"found: {confirmed} confirming updates, std {pos_std * 100:.2f} cm, {rot_std:.2f} deg{check}",
        **base,
    )


def _worth_another(ekf: PoseEKF, confirmed: int, cfg: LocalSearchConfig) -> bool:
    """Past ``cfg.refine_frames``: is the track confirmed and healthy, with its pose still above the
    "small covariance" bounds, so that another frame may bring it under them?"""
    if ekf.divergence is not None or confirmed < cfg.confirm_updates:
        return False
    pos_std, rot_std = pose_stds(ekf)
    return pos_std > cfg.max_position_std_m or rot_std > cfg.max_rotation_std_deg


@dataclass(frozen=True)
class Track:
    """A refined track (:func:`refine_track`): found or why not, and the last estimate and frame."""

    found: bool
    reason: str
    estimate: PoseEstimate
    frame: StereoFrame
    n_inliers: int
    position_std_m: float
    rotation_std_deg: float
    G_WO: np.ndarray
