"""One episode's sensing: a profile's per-episode draws and its seeded generators."""

from __future__ import annotations

import numpy as np

from lab.robot import StereoCamera
from lab.sim.room_errors import RoomDraw
from lab.sim.sensing import SensingProfile, corrupt_stereo, odometry_increment

__all__ = ["EpisodeSensing"]


class EpisodeSensing:
    """A profile's per-episode draws and its seeded generators, for one :class:`lab.sim.SimRobot`.

    Each model has its own streams (children of ``numpy.random.SeedSequence(seed)``, none of them the
    stream of ``default_rng(seed)`` that :class:`lab.sim.OdometryNoise` draws from), so that the images
    do not depend on how far the robot drove, nor the odometry on how often it looked. The draws come
    from the profile as the world draws it (:meth:`SensingProfile.drawn`: the stated sigmas the robot is
    told, times the mismatch factor).

    Parameters
    ----------
    profile : SensingProfile
        As stated (``self.profile``); ``self.world`` is the one drawn from.
    seed : int or None
        As for ``numpy.random.default_rng``.
    camera : StereoCamera
        The nominal camera (what the robot reports).
    light_direction : tuple of 3 floats
        The renderer's nominal light (``RenderSettings.light_direction``).
    """

    def __init__(self, profile: SensingProfile, seed: int, camera: StereoCamera, light_direction):
        self.profile = profile
        self.world = world = profile.drawn()
        streams = np.random.SeedSequence(seed).spawn(7)  # the first five as before the room's errors
        cam, odo, pt, image, noise, room, slip = (np.random.default_rng(s) for s in streams)
        self.camera = world.camera.draw(cam, camera, light_direction)
        self.odometry = world.odometry.draw(odo)
        self.pan_tilt = world.pan_tilt.draw(pt)
        self.room: RoomDraw = world.room.draw(room)
        self._image_rng = image
        self._odometry_rng = noise
        self._slip_rng = slip

    def render_stereo(self, world, G_WC: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pair the camera delivers: rendered with this episode's calibration and light, corrupted."""
        d = self.camera
        left, right = world.render_stereo(G_WC, d.render_camera, light_direction=d.light_direction)
        return self.corrupt(left, right)

    def corrupt(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A rendered pair as this episode's camera delivers it (:func:`corrupt_stereo` with this
        episode's draw and capture noise); a rehearsal renders its raw pair itself and corrupts it here."""
        return corrupt_stereo(left, right, self.world.camera, self.camera, self._image_rng)

    def odometry_increment(self, ds: float, dth: float, wheel_base: float) -> tuple[float, float]:
        z_left, z_right = self._odometry_rng.standard_normal(2)
        ds_m, dth_m = odometry_increment(
            self.world.odometry, self.odometry, ds, dth, wheel_base, z_left, z_right
        )
        return float(ds_m), float(dth_m)

    def bump_slip(self) -> tuple[float, float, float]:
        """One bump's jump of the true pose (:meth:`lab.sim.room_errors.RoomErrors.slip`)."""
        return self.world.room.slip(self._slip_rng)
