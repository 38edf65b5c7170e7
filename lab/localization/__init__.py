"""Localization against the room: an EKF over the robot's planar pose, corrected by stereo landmarks.

Both papers take the robot's pose from wheel odometry alone; here the odometry is corrected by
landmarks, posters on the walls whose poses are known. The data flow::

    odometry -- odometry_increment --> u --Localizer.predict--> (x_bar, Sigma_bar)
    stereo frame --LandmarkObserver.candidates / observe--> LandmarkObservation (z, Q)
      --Localizer.update (gated, iterated EKF)--> (x, Sigma), UpdateRecord
    LocalizedRobot: the estimate behind the Robot interface (odometry(), frames' odom,
      pose_estimate() -> PlanarPoseEstimate), active re-localization and report detours

Modules: :mod:`~lab.localization.modes` (:class:`LocalizationMode`), :mod:`~lab.localization.models`
(the planar motion and measurement models and their Jacobians), :mod:`~lab.localization.filter` (the
filter: :class:`LocalizerConfig`, :class:`Localizer`, its records; the equations are in its
docstring), :mod:`~lab.localization.observer` (finding landmarks in frames),
:mod:`~lab.localization.robot` (:class:`LocalizedRobot`), :mod:`~lab.localization.landmarks` (the
landmark map, built by :mod:`lab.training.landmarks`), :mod:`~lab.localization.posters` (a surveyed map's
posters in the filter's state), :mod:`~lab.localization.refind` (re-finding a robot whose estimate the
gate has lost), :mod:`~lab.localization.stamps` (the odometry at an image's stamp) and
:mod:`~lab.localization.survey_limit` (the error a surveyed map leaves at best: how many posters to hang)
and :mod:`~lab.localization.survey_tour` (a tour that ties a surveyed map's posters together).
"""

from lab.localization.filter import Localizer, LocalizerConfig, PlanarPoseEstimate, UpdateRecord
from lab.localization.landmarks import Landmark, LandmarkMap, inward_normal
from lab.localization.models import (
    calibrated_motion_jacobians,
    calibrated_motion_model,
    measurement_jacobian,
    measurement_model,
    motion_jacobians,
    motion_model,
    observation_of,
    odometry_increment,
    pose_from_observation,
    spin_fraction,
)
from lab.localization.modes import LocalizationMode
from lab.localization.observer import LandmarkObservation, LandmarkObserver, face_share_in_image
from lab.localization.posters import PosterStates
from lab.localization.robot import LocalizedRobot
from lab.localization.stamps import OdometryHistory, PanTiltHistory, interpolate_pose

__all__ = [
    "Landmark",
    "LandmarkMap",
    "LandmarkObservation",
    "LandmarkObserver",
    "LocalizationMode",
    "LocalizedRobot",
    "Localizer",
    "LocalizerConfig",
    "OdometryHistory",
    "PanTiltHistory",
    "PlanarPoseEstimate",
    "PosterStates",
    "UpdateRecord",
    "calibrated_motion_jacobians",
    "calibrated_motion_model",
    "face_share_in_image",
    "interpolate_pose",
    "inward_normal",
    "measurement_jacobian",
    "measurement_model",
    "motion_jacobians",
    "motion_model",
    "observation_of",
    "odometry_increment",
    "pose_from_observation",
    "spin_fraction",
]
