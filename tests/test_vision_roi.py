"""Regions of interest while tracking: what they keep and what they drop.

Ground truth from the simulator: the box's pixels (the segmentation) and its true pose. The peer of the
region's features is the full frame's extraction.
"""

import math

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.estimation import PoseEKF
from lab.geometry import G_to_pose6, Pose2D, Ry, se3, se3_inv, transform_points
from lab.identification.agent import IdentificationAgent
from lab.robot import BaseLimits, PanTiltLimits, StereoCamera
from lab.sim import SimRobot, SimWorld, load_box_models
from lab.training import get_database
from lab.vision import StereoParams, stereo_features
from lab.vision.roi import RegionOfInterest, box_corners, object_roi, tracked_roi
from lab.vision.stereo import (
    _epipolar_matches,
    _grey,
    _in_disparities,
    _roi_rects,
    detect_in,
    sift,
    triangulate,
)

CAM = StereoCamera.from_fov(mount_R=(0.0, 0.0, 0.7))
SIGMA_RV = np.diag([0.01**2] * 3 + [math.radians(3.0) ** 2] * 3)  # a tracked pose: 1 cm, 3 deg


@pytest.fixture(scope="module")
def scene():
    """A rendered frame of model M1's box 1 m in front of the robot, turned 23 degrees, the head aimed
    a little beside it: the frame, the box's true G_CO, its pixels in the left image, its extent, the
    depth buffer [m]."""
    spec = load_box_models()[1]
    with SimWorld("box_database") as w:
        carrier = w.add_carrier(spec, Pose2D(0.0, 0.0, 0.0), box_yaw=0.4)
        # realistic's sensors in an exact room: the region's feature-for-feature checks ran on this image
        robot = SimRobot(w, start=Pose2D(-1.0, 0.0, 0.0), seed=0, sensing="sensors")
        robot.enable()
        c = carrier.G_WO[:3, 3]
        tilt = math.atan2(c[2] - robot.camera.mount_R[2], 1.0)
        robot.command_pan_tilt(0.12, tilt)
        robot.wait_pan_tilt()
        frame = robot.capture_stereo()
        G_WC = w.truth.G_WC()
        G_CO = se3_inv(G_WC) @ carrier.G_WO
        seg = w.truth.segmentation(G_WC, robot.camera)
        box_pixels = np.argwhere(seg == w.body_id(carrier.name))[:, ::-1]  # (u, v)
        depth = w.truth.depth(G_WC, robot.camera)
    db = get_database(spec.name, progress=False)
    return frame, G_CO, box_pixels, np.asarray(db.extent), depth


def test_the_region_holds_the_true_box(scene):
    """Predicted 1.5 standard deviations off the truth, the 3-sigma region still holds every pixel of the
    box (the segmentation) and the disparities of the box's corners."""
    frame, G_CO, box_pixels, extent, _ = scene
    assert len(box_pixels) > 500
    off = G_CO @ se3(Ry(1.5 * math.radians(3.0)))  # 1.5 sigma off in rotation and on each axis
    off[:3, 3] += 1.5 * 0.01 * np.array([1.0, -1.0, 1.0])
    roi = tracked_roi([(off, SIGMA_RV)], extent, frame.camera, 0.5, 96.0, margin_px=0.0, n_sigma=3.0)
    assert roi is not None
    assert roi.contains(box_pixels + 0.5).all()  # pixel centres
    z = transform_points(G_CO, box_corners(extent))[:, 2]
    d = frame.camera.fx * frame.camera.baseline / z
    assert roi.min_disparity <= d.min() and d.max() <= roi.max_disparity
    assert roi.area < 0.5 * frame.camera.width * frame.camera.height  # and it is a region


def test_features_outside_the_region_are_not_extracted(scene):
    """Every feature lies inside the region and its right partner inside the right band; most are the
    full frame's features at the same pixel and 3D point."""
    frame, G_CO, _, extent, _ = scene
    roi = tracked_roi([(G_CO, SIGMA_RV)], extent, frame.camera, 0.5, 96.0)
    full = stereo_features(frame.left, frame.right, frame.camera)
    f = stereo_features(frame.left, frame.right, frame.camera, roi=roi)
    assert 20 <= len(f) < 0.7 * len(full)
    assert roi.contains(f.uv).all()
    assert ((f.disparity >= roi.min_disparity) & (f.disparity <= roi.max_disparity)).all()
    band = roi.right_band(frame.camera, StereoParams().max_dy)
    uv_r = f.uv - np.stack([f.disparity, np.zeros(len(f))], axis=1)
    assert band.contains(uv_r).all()
    assert not roi.contains(full.uv).all()  # the full frame has features the region drops
    # the full frame's features inside the region and its disparities are (almost all) found again, at
    # the same pixel and 3D point (SIFT on the crop differs only at the coarse octaves, whose blur the
    # crop cuts: with the 8 px pad one right partner here sits 0.002 px off, moving its point 0.1 mm,
    # under 1 % of its own standard deviation), and the region adds few of its own (its matches are
    # made over the whole disparity range, as the full frame's)
    in_range = (full.disparity >= roi.min_disparity) & (full.disparity <= roi.max_disparity)
    peer = full.subset(roi.contains(full.uv) & in_range)
    gap = np.abs(peer.uv[:, None, :] - f.uv[None, :, :]).sum(axis=2)
    nearest = gap.argmin(axis=1)
    found = gap[np.arange(len(peer)), nearest] < 1e-3
    assert len(peer) >= 20 and found.mean() >= 0.8
    assert np.abs(peer.disparity[found] - f.disparity[nearest[found]]).max() < 0.01  # px
    sd = np.sqrt(np.einsum("nii->ni", f.covariances[nearest[found]]))
    assert (np.abs(peer.points_C[found] - f.points_C[nearest[found]]) <= 0.01 * sd).all()
    assert found.sum() >= 0.8 * len(f) - 1e-9


def test_the_pad_is_the_context_sift_sees_around_a_region(scene):
    """SIFT on the region alone (pad 0) finds keypoints that the full frame does not have, near the
    crop's border where its blur is cut; with the default pad more of the region's keypoints are the
    full frame's (same position, size and descriptor). A negative or fractional pad is refused."""
    frame, G_CO, _, extent, _ = scene
    roi = tracked_roi([(G_CO, SIGMA_RV)], extent, frame.camera, 0.5, 96.0)
    grey = _grey(frame.left)
    det = sift()
    kp, des = det.detectAndCompute(grey, None)
    full = {(round(k.pt[0], 3), round(k.pt[1], 3), round(k.size, 3)): d for k, d in zip(kp, des, strict=True)}

    def share_of_full(pad):
        kp, des = detect_in(grey, roi.rect, det, pad)
        assert roi.contains(np.array([k.pt for k in kp])).all()
        keys = [(round(k.pt[0], 3), round(k.pt[1], 3), round(k.size, 3)) for k in kp]
        return np.mean([q in full and np.array_equal(full[q], d) for q, d in zip(keys, des, strict=True)])

    default = share_of_full(StereoParams().roi_pad_px)
    assert share_of_full(0) < default <= share_of_full(32) + 1e-9
    assert default >= 0.6  # this view: 0.60, 0.68, 0.79, 0.79 with 0, 8, 16, 32 px
    for bad in (-1, 2.5):
        with pytest.raises(ConfigError, match="roi_pad_px"):
            StereoParams(roi_pad_px=bad)


def test_the_features_are_those_of_the_keypoints_moved_one_by_one(scene):
    """The pipeline reads the keypoints' pixels as arrays (no loop over them): its features are, bit for
    bit, those of :func:`detect_in`'s keypoints, each moved to the whole image's pixels, matched and
    triangulated; with a region and without."""
    frame, G_CO, _, extent, _ = scene
    roi = tracked_roi([(G_CO, SIGMA_RV)], extent, frame.camera, 0.5, 96.0)
    params = StereoParams()
    det = sift()
    for region in (roi, None):
        rects = (None, None) if region is None else _roi_rects(region, frame.camera, params)
        kl, dl = detect_in(_grey(frame.left), rects[0], det, params.roi_pad_px)
        kr, dr = detect_in(_grey(frame.right), rects[1], det, params.roi_pad_px)
        il, ir = _epipolar_matches(kl, dl, kr, dr, params)
        uv_l = np.array([kl[i].pt for i in il])
        uv_r = np.array([kr[i].pt for i in ir])
        keep = _in_disparities(region, uv_l[:, 0] - uv_r[:, 0])
        if keep is not None:
            il, uv_l, uv_r = il[keep], uv_l[keep], uv_r[keep]
        f = stereo_features(frame.left, frame.right, frame.camera, params, roi=region)
        assert len(f) == len(il) > 20
        assert np.array_equal(f.uv, uv_l)
        assert np.array_equal(f.disparity, uv_l[:, 0] - uv_r[:, 0])
        assert np.array_equal(f.points_C, triangulate(uv_l, uv_r, frame.camera))
        assert np.array_equal(f.descriptors, dl[il])


def test_the_regions_features_lie_where_the_depth_buffer_says(scene):
    """Against the rendered depth: the region's features are no farther off than the full frame's in the
    same region (matching over the region's disparities alone would seat background features at the
    box's depth)."""
    frame, G_CO, _, extent, depth = scene
    roi = tracked_roi([(G_CO, SIGMA_RV)], extent, frame.camera, 0.5, 96.0)
    full = stereo_features(frame.left, frame.right, frame.camera)
    full = full.subset(
        roi.contains(full.uv) & (full.disparity >= roi.min_disparity) & (full.disparity <= roi.max_disparity)
    )
    f = stereo_features(frame.left, frame.right, frame.camera, roi=roi)

    def off(F):  # features more than 5 cm from the depth buffer at their pixel
        u, v = (np.clip(np.rint(F.uv[:, i]).astype(int), 0, n - 1) for i, n in ((0, 320), (1, 240)))
        return int(np.count_nonzero(np.abs(F.points_C[:, 2] - depth[v, u]) > 0.05))

    assert off(f) <= off(full) + 3 and len(f) <= len(full) + 5


def test_a_plain_rectangle_is_the_search_refinements_region(scene):
    """The search's ``object_roi`` rectangle: features only inside it, partners over the whole range."""
    frame, G_CO, _, extent, _ = scene
    rect = object_roi(G_CO, extent, frame.camera, 20)
    f = stereo_features(frame.left, frame.right, frame.camera, roi=rect)
    x, y, w, h = rect
    assert len(f) > 0
    assert ((f.uv[:, 0] >= x) & (f.uv[:, 0] < x + w) & (f.uv[:, 1] >= y) & (f.uv[:, 1] < y + h)).all()


def test_no_region_when_lost_behind_or_too_large():
    G = np.eye(4)
    G[:3, 3] = (0.0, 0.0, 1.0)
    ext = (0.28, 0.28, 0.28)
    roi = tracked_roi([(G, SIGMA_RV)], ext, CAM, 0.5, 96.0)
    assert isinstance(roi, RegionOfInterest)
    assert tracked_roi([], ext, CAM, 0.5, 96.0) is None  # no pose
    behind = G.copy()
    behind[2, 3] = -1.0
    assert tracked_roi([(G, SIGMA_RV), (behind, SIGMA_RV)], ext, CAM, 0.5, 96.0) is None
    near = G.copy()
    near[2, 3] = 0.4  # the box fills most of the image
    assert tracked_roi([(near, SIGMA_RV)], ext, CAM, 0.5, 96.0, max_fraction=0.6) is None
    wide = np.diag([0.2**2] * 3 + [0.3**2] * 3)  # an uncertain pose: the grown box fills the image
    assert tracked_roi([(G, wide)], ext, CAM, 0.5, 96.0) is None
    # two poses: the union of their boxes
    right = G.copy()
    right[0, 3] = 0.5
    both = tracked_roi([(G, SIGMA_RV), (right, SIGMA_RV)], ext, CAM, 0.5, 96.0, max_fraction=1.0)
    assert both.x == roi.x and both.x + both.w > roi.x + roi.w


class _Robot:
    def __init__(self, camera):
        self.camera, self.pan_tilt_limits, self.base_limits = camera, PanTiltLimits(), BaseLimits()


def test_the_agent_looks_at_the_tracked_box_and_returns_to_the_full_frame_when_lost(scene):
    frame, G_CO, _, _, _ = scene
    cam = frame.camera
    dbs = [get_database(f"M{i}", progress=False) for i in range(4)]
    agent = IdentificationAgent(_Robot(cam), dbs, None, planner="random", seed=0)
    assert agent.region_of_interest(agent.bank.estimates, cam) is None  # no filter has a pose
    f: PoseEKF = agent.bank[2]
    f.initialize(G_to_pose6(G_CO), None, Sigma_rv=SIGMA_RV)
    roi = agent.region_of_interest(agent.bank.estimates, cam)
    assert roi is not None and roi.area < 0.6 * cam.width * cam.height
    feats, _ = agent._perceive(frame)
    assert agent.last_roi == roi and roi.contains(feats.uv).all()
    agent._lost = True  # the track is lost: the full frame
    assert agent.region_of_interest(agent.bank.estimates, cam) is None
    feats, _ = agent._perceive(frame)
    assert agent.last_roi is None and not roi.contains(feats.uv).all()
    from dataclasses import replace

    agent._lost = False
    agent.config = replace(agent.config, roi=False)
    assert agent.region_of_interest(agent.bank.estimates, cam) is None
