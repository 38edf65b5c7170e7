"""Vision: stereo 3D SIFT features, feature databases and matching, colour models, rectification.

``stereo_features`` turns a rectified pair into the measurement D_k (3D points in the camera frame C
with descriptors and covariances); ``FeatureDatabase`` is an object's trained database B_i (built by
:mod:`lab.training`); ``Matcher`` gives the correspondences J_i; ``back_project`` the colour
likelihood map of the global search; ``StereoRectifier`` turns a real camera's raw pairs into rectified ones.
"""

from lab.vision.colour import back_project, chromaticity, colour_histogram
from lab.vision.database import FeatureDatabase, load_database, save_database
from lab.vision.dense import dense_points, disparity_map
from lab.vision.matching import Correspondences, JointIndex, Matcher
from lab.vision.rectify import StereoCalibration, StereoRectifier, load_calibration
from lab.vision.stereo import Features3D, StereoParams, stereo_features, triangulate

__all__ = [
    "Correspondences",
    "FeatureDatabase",
    "Features3D",
    "JointIndex",
    "Matcher",
    "StereoCalibration",
    "StereoParams",
    "StereoRectifier",
    "back_project",
    "chromaticity",
    "colour_histogram",
    "dense_points",
    "disparity_map",
    "load_calibration",
    "load_database",
    "save_database",
    "stereo_features",
    "triangulate",
]
