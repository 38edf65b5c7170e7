"""Vision: stereo 3D SIFT features, feature databases and matching, colour models, rectification.

``stereo_features`` turns a rectified pair into the measurement D_k (3D points in the camera frame C
with descriptors and covariances); ``get_database`` returns an object's trained database B_i (building
and caching it on first use); ``Matcher`` gives the correspondences J_i; ``back_project`` the colour
likelihood map of the global search; ``StereoRectifier`` turns a real camera's raw pairs into rectified ones.
"""

from lab.vision.colour import back_project, chromaticity, colour_histogram
from lab.vision.database import (
    Correspondences,
    FeatureDatabase,
    Matcher,
    TrainingParams,
    get_database,
    load_database,
    save_database,
    train_database,
    trainable_objects,
)
from lab.vision.dense import dense_points, disparity_map
from lab.vision.rectify import StereoCalibration, StereoRectifier, load_calibration
from lab.vision.stereo import Features3D, StereoParams, stereo_features, triangulate

__all__ = [
    "Correspondences",
    "FeatureDatabase",
    "Features3D",
    "Matcher",
    "StereoCalibration",
    "StereoParams",
    "StereoRectifier",
    "TrainingParams",
    "back_project",
    "chromaticity",
    "colour_histogram",
    "dense_points",
    "disparity_map",
    "get_database",
    "load_calibration",
    "load_database",
    "save_database",
    "stereo_features",
    "train_database",
    "trainable_objects",
    "triangulate",
]
