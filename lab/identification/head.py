r"""Pan-tilt control of the identification paper (Sec. IV): *tracking* and *scanning*.

Tracking keeps the probability-weighted object origin :math:`P_{obj}` in the image centre. Its image
position is Eq. (16),

.. math:: p_{obj} = \begin{bmatrix} f x_{obj} / z_{obj} + c_x \\ f y_{obj} / z_{obj} + c_y \end{bmatrix},

and a proportional law sets the pan (and tilt) slew rate, Eq. (17),

.. math:: u_{pan} = K (c_x - x_{img}), \qquad u_{tilt} = K (c_y - y_{img}).

(The paper writes :math:`-K(c_x - x_{img})`: its pan is positive to the right; ours is positive to the
left, counter-clockwise seen from above, see ``docs/conventions.md``.) The rate is applied as a
position target one control period ahead, which is how a PTU-D46 in position mode is driven.

Scanning sweeps a pattern of pan angles at a fixed tilt, at start-up and whenever the track is lost;
the base halts while it scans (the paper's HALT).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from lab.robot import PanTiltLimits, PanTiltState, StereoCamera

__all__ = ["HeadMode", "HeadConfig", "HeadCommand", "HeadController", "image_position"]


class HeadMode(Enum):
    TRACKING = "tracking"
    SCANNING = "scanning"


@dataclass(frozen=True)
class HeadConfig:
    """Gains and patterns of the head controller.

    Attributes
    ----------
    K : float [rad/s per px]
        Proportional gain of Eq. (17).
    max_rate : float [rad/s]
        Largest commanded slew rate.
    scan_pans_deg : tuple of float
        The scanning sweep, visited in order and then backwards.
    scan_tilt_deg : float
    """

    K: float = 0.012
    max_rate: float = math.radians(60.0)
    scan_pans_deg: tuple[float, ...] = (
        0.0,
        30.0,
        60.0,
        90.0,
        60.0,
        30.0,
        0.0,
        -30.0,
        -60.0,
        -90.0,
        -60.0,
        -30.0,
    )
    scan_tilt_deg: float = -10.0


@dataclass(frozen=True)
class HeadCommand:
    pan: float  # target [rad]
    tilt: float  # target [rad]
    mode: HeadMode
    p_img: tuple[float, float] | None = None  # Eq. (16): where the tracked origin is in the image [px]


def image_position(P_obj_C: np.ndarray, camera: StereoCamera) -> tuple[float, float]:
    """Eq. (16): pixel position of a point in the camera frame C."""
    x, y, z = (float(v) for v in P_obj_C)
    return camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy


class HeadController:
    """Tracking (Eq. (16)-(17)) when an object origin is known, scanning otherwise.

    Parameters
    ----------
    camera : StereoCamera
    limits : PanTiltLimits
    config : HeadConfig, optional
    """

    def __init__(self, camera: StereoCamera, limits: PanTiltLimits, config: HeadConfig | None = None):
        self.camera, self.limits = camera, limits
        self.config = config or HeadConfig()
        self._scan_index = 0

    def _clip(self, pan: float, tilt: float) -> tuple[float, float]:
        L = self.limits
        return float(np.clip(pan, L.pan_min, L.pan_max)), float(np.clip(tilt, L.tilt_min, L.tilt_max))

    def command(self, state: PanTiltState, P_obj_C: np.ndarray | None, dt: float) -> HeadCommand:
        """The next pan-tilt target for a control period ``dt`` [s].

        ``P_obj_C`` is the probability-weighted object origin in the current camera frame C, or None
        when no model is tracked (then: scan).
        """
        cfg = self.config
        if P_obj_C is not None and P_obj_C[2] > 0.05:
            x_img, y_img = image_position(P_obj_C, self.camera)
            u_pan = cfg.K * (self.camera.cx - x_img)  # Eq. (17), our pan is positive to the left
            u_tilt = cfg.K * (self.camera.cy - y_img)
            u_pan, u_tilt = (float(np.clip(u, -cfg.max_rate, cfg.max_rate)) for u in (u_pan, u_tilt))
            pan, tilt = self._clip(state.pan + u_pan * dt, state.tilt + u_tilt * dt)
            return HeadCommand(pan, tilt, HeadMode.TRACKING, (x_img, y_img))
        pans = cfg.scan_pans_deg
        target = math.radians(pans[self._scan_index % len(pans)])
        tilt = math.radians(cfg.scan_tilt_deg)
        if abs(state.pan - target) < math.radians(1.0) and abs(state.tilt - tilt) < math.radians(1.0):
            self._scan_index += 1
            target = math.radians(pans[self._scan_index % len(pans)])
        pan, tilt = self._clip(target, tilt)
        return HeadCommand(pan, tilt, HeadMode.SCANNING)
