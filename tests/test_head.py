"""Pan-tilt tracking (Eq. (16)-(17)) centres the object; scanning sweeps its pattern."""

import math

import numpy as np

from lab.geometry import Pose2D, se3_inv, transform_points
from lab.identification.head import HeadController, HeadMode, image_position
from lab.sim import SimRobot, SimWorld, load_box_models


def test_tracking_brings_the_object_to_the_image_centre():
    with SimWorld("arena") as w:
        c = w.add_carrier(load_box_models()[0], Pose2D(0.0, 0.0, 0.0))
        r = SimRobot(w, start=Pose2D(-1.2, 0.6, 0.0))  # the box is ~27 deg to the right
        r.enable()
        head = HeadController(r.camera, r.pan_tilt_limits)
        dt = 0.1
        for _ in range(60):
            P_C = transform_points(se3_inv(w.truth.G_WC()), c.G_WO[:3, 3])  # test input: the true origin
            cmd = head.command(r.pan_tilt(), P_C, dt)
            assert cmd.mode is HeadMode.TRACKING
            r.command_pan_tilt(cmd.pan, cmd.tilt)
            r.step(dt)
        P_C = transform_points(se3_inv(w.truth.G_WC()), c.G_WO[:3, 3])
        u, v = image_position(P_C, r.camera)
        assert abs(u - r.camera.cx) < 3 and abs(v - r.camera.cy) < 3
        assert r.pan_tilt().pan < -math.radians(20)  # it panned right (negative), towards the box


def test_scanning_sweeps_the_pattern_when_nothing_is_tracked():
    with SimWorld("arena") as w:
        r = SimRobot(w)
        r.enable()
        head = HeadController(r.camera, r.pan_tilt_limits)
        seen = set()
        for _ in range(400):
            cmd = head.command(r.pan_tilt(), None, 0.1)
            assert cmd.mode is HeadMode.SCANNING
            r.command_pan_tilt(cmd.pan, cmd.tilt)
            r.step(0.1)
            seen.add(round(math.degrees(r.pan_tilt().pan)))
        assert {-90, 90, 0} <= seen
        assert np.isclose(r.pan_tilt().tilt, math.radians(head.config.scan_tilt_deg))
