"""pincal: robot kinematic calibration on Pinocchio.

Identify the kinematic parameters of a URDF from measurements of the real
robot and write a corrected URDF. The first method is Franaszek & Marvel
(2022), "Using Full Pose Measurement for Serial Robot Calibration".
"""

__version__ = "0.1.0"

from .chain_calibration import ChainCalibration, calibrate_chain
from .chain import ChainPoses, KinematicChain, pose_from_xyz_rpy, xyz_rpy_from_pose
from .dh import KUKA_LWR4_DH, TABLE2_LARGE, TABLE2_SMALL, DHDeviations, DHTable
from .dh_parameters import DHParameterSet
from .errors import CalibrationError, MeasurementError, ModelError, PincalError
from .measurements import JointSpec, MeasurementSet, read_measurements, write_measurements
from .metrics import ErrorSummary, PoseErrors, pose_errors
from .ml_estimator import MLCalibration, calibrate_ml
from .noise_limit import PredictedErrors, predicted_errors
from .parameter_sets import JointOffsets, PlacementErrors
from .paper_methods import PaperCalibration, calibrate_paper
from .registration import Registration, register_orientations, register_points
from .simulation import SimulatedExperiment, SimulationSettings, simulate_experiment

__all__ = [
    "__version__",
    "CalibrationError",
    "ChainCalibration",
    "JointOffsets",
    "MLCalibration",
    "PlacementErrors",
    "PredictedErrors",
    "calibrate_chain",
    "calibrate_ml",
    "predicted_errors",
    "ChainPoses",
    "DHDeviations",
    "DHParameterSet",
    "DHTable",
    "ErrorSummary",
    "JointSpec",
    "KUKA_LWR4_DH",
    "KinematicChain",
    "MeasurementError",
    "MeasurementSet",
    "ModelError",
    "PaperCalibration",
    "PincalError",
    "PoseErrors",
    "Registration",
    "SimulatedExperiment",
    "SimulationSettings",
    "TABLE2_LARGE",
    "TABLE2_SMALL",
    "calibrate_paper",
    "pose_errors",
    "pose_from_xyz_rpy",
    "read_measurements",
    "register_orientations",
    "register_points",
    "simulate_experiment",
    "write_measurements",
    "xyz_rpy_from_pose",
]
