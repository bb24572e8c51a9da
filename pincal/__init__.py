"""pincal: robot kinematic calibration on Pinocchio.

Identify the kinematic parameters of a URDF from measurements of the real
robot and write a corrected URDF. The first method is Franaszek & Marvel
(2022), "Using Full Pose Measurement for Serial Robot Calibration".
"""

from typing import TYPE_CHECKING

from pincal._version import __version__
from pincal.errors import CalibrationError, MeasurementError, ModelError, PincalError

#: Where each public name is defined. ``import pincal`` imports none of these modules: a name's
#: module is imported on its first use (PEP 562 ``__getattr__`` below), so the command line and each
#: study worker load only what they run (``pincal calibrate`` neither the planner nor the diagnosis).
_DEFINED_IN = {
    "pincal.fit.chain_calibration": ("ChainCalibration", "ChainFitOptions", "calibrate_chain"),
    "pincal.fit.fixture_calibration": ("FixtureCalibration", "calibrate_fixture"),
    "pincal.fit.level_choice": ("LevelChoice", "choose_fixture_level", "choose_level"),
    "pincal.fit.socket_metrics": ("FixtureMetrics", "fixture_metrics"),
    "pincal.fit.metrics": ("ErrorSummary", "PoseErrors", "RowCorrections", "pose_errors"),
    "pincal.paper.ml_estimator": ("MLCalibration", "MLSettings", "calibrate_ml"),
    "pincal.paper.noise_limit": ("PredictedErrors", "predicted_errors"),
    "pincal.paper.methods": ("PaperCalibration", "calibrate_paper"),
    "pincal.fit.registration": ("register_orientations", "register_points"),
    "pincal.measurements.csv_v1": ("read_measurements", "read_sessions", "write_measurements"),
    "pincal.measurements.bags": ("read_bag",),
    "pincal.measurements.plateaus": ("PlateauSettings", "extract_postures"),
    "pincal.measurements.fixture": ("Fixture", "FixtureData", "read_fixture", "read_fixture_data"),
    "pincal.measurements.data": ("JointSpec", "MeasurementSet"),
    "pincal.model.chain": ("ChainPoses", "KinematicChain", "pose_from_xyz_rpy", "xyz_rpy_from_pose"),
    "pincal.model.tree": ("KinematicTree", "TargetSpec", "parse_targets"),
    "pincal.fit.tree_calibration": ("TreeCalibration", "calibrate_tree"),
    "pincal.model.dh.table": ("KUKA_LWR4_DH", "TABLE2_LARGE", "TABLE2_SMALL", "DHDeviations", "DHTable"),
    "pincal.model.dh.files": ("read_dh_csv",),
    "pincal.model.dh.parameters": ("DHParameterSet",),
    "pincal.model.dh.robot": ("DHRobot",),
    "pincal.model.parameter_sets": ("JointOffsets", "PlacementErrors"),
    "pincal.model.sensor": ("Registration",),
    "pincal.simulation.paper": ("SimulatedExperiment", "SimulationSettings", "simulate_experiment"),
    # the file-level jobs of the commands, each taking paths and a settings value
    "pincal.workflows.settings": ("CalibrateSettings", "DiagnoseSettings", "EvaluateSettings"),
    "pincal.workflows.calibration": ("CalibrationRun", "calibrate_files"),
    "pincal.workflows.tree_calibration": ("TreeCalibrationRun", "calibrate_tree_files"),
    "pincal.workflows.tree_evaluation": ("TreeEvaluation", "evaluate_tree_files"),
    "pincal.workflows.tree_diagnosis": ("TreeDiagnoseRun", "diagnose_tree_files"),
    "pincal.diagnosis.tree_diagnose": ("TreeDiagnosis", "diagnose_tree"),
    "pincal.workflows.diagnosis": ("DiagnoseOutputs", "DiagnoseRun", "diagnose_files"),
    "pincal.workflows.evaluation": ("Evaluation", "SessionEvaluation", "evaluate_files"),
    "pincal.workflows.evaluation_outputs": ("EvaluateOutputs", "EvaluateRun", "ThresholdFailure", "evaluate_and_write"),
    "pincal.workflows.report_page": ("report_file",),
    "pincal.workflows.fixture": ("FixtureRun", "FixtureEvaluation", "calibrate_fixture_files",
                                 "evaluate_fixture_files"),
    "pincal.planning.planner": ("PlanSettings",),
    "pincal.workflows.preparation": ("PlanInputs", "PlanRun", "plan_files", "urdf_from_dh_file"),
    "pincal.planning.camera_plan": ("CameraPlanSettings",),
    "pincal.workflows.camera_plan": ("CameraPlanInputs", "CameraPlanRun", "camera_plan_files"),
    "pincal.workflows.extract": ("BagRead", "CutFailed", "ImageExtraction", "NoPostures", "extract_file",
                                 "extract_images"),
    "pincal.measurements.charuco": ("CharucoSpec", "parse_board"),
    "pincal.workflows.detection": ("DetectSettings", "DetectRun", "detect_files"),  # imports OpenCV
    "pincal.workflows.camera_calibration": ("CameraCalibrateSettings", "CameraCalibrationRun",
                                            "calibrate_camera_files"),
    "pincal.workflows.camera_evaluation": ("CameraEvaluateSettings", "CameraEvaluation", "evaluate_camera_files"),
    "pincal.workflows.camera_simulation": ("CameraSimulationSettings", "CameraSimulation", "simulate_camera_files"),
    "pincal.workflows.camera_diagnosis": ("CameraDiagnoseSettings", "CameraDiagnoseRun", "diagnose_camera_files"),
    "pincal.diagnosis.camera_diagnose": ("CameraDiagnosis", "diagnose_camera"),
    "pincal.workflows.simulation": ("simulate_to_directory",),
    "pincal.model.dh.urdf": ("dh_robot_from_urdf", "urdf_from_dh"),  # imports yourdfpy
    "pincal.report.html": ("render_html", "write_html"),  # imports jinja2 and matplotlib
}

if TYPE_CHECKING:  # what static analysers see; at run time the names come from __getattr__
    from pincal.diagnosis.camera_diagnose import CameraDiagnosis, diagnose_camera
    from pincal.diagnosis.tree_diagnose import TreeDiagnosis, diagnose_tree
    from pincal.fit.chain_calibration import ChainCalibration, ChainFitOptions, calibrate_chain
    from pincal.fit.fixture_calibration import FixtureCalibration, calibrate_fixture
    from pincal.fit.level_choice import LevelChoice, choose_fixture_level, choose_level
    from pincal.fit.metrics import ErrorSummary, PoseErrors, RowCorrections, pose_errors
    from pincal.fit.registration import register_orientations, register_points
    from pincal.fit.socket_metrics import FixtureMetrics, fixture_metrics
    from pincal.fit.tree_calibration import TreeCalibration, calibrate_tree
    from pincal.measurements.bags import read_bag
    from pincal.measurements.charuco import CharucoSpec, parse_board
    from pincal.measurements.csv_v1 import (
        read_measurements,
        read_sessions,
        write_measurements,
    )
    from pincal.measurements.data import JointSpec, MeasurementSet
    from pincal.measurements.fixture import (
        Fixture,
        FixtureData,
        read_fixture,
        read_fixture_data,
    )
    from pincal.measurements.plateaus import PlateauSettings, extract_postures
    from pincal.model.chain import (
        ChainPoses,
        KinematicChain,
        pose_from_xyz_rpy,
        xyz_rpy_from_pose,
    )
    from pincal.model.dh.files import read_dh_csv
    from pincal.model.dh.parameters import DHParameterSet
    from pincal.model.dh.robot import DHRobot
    from pincal.model.dh.table import (
        KUKA_LWR4_DH,
        TABLE2_LARGE,
        TABLE2_SMALL,
        DHDeviations,
        DHTable,
    )
    from pincal.model.dh.urdf import dh_robot_from_urdf, urdf_from_dh
    from pincal.model.parameter_sets import JointOffsets, PlacementErrors
    from pincal.model.sensor import Registration
    from pincal.model.tree import KinematicTree, TargetSpec, parse_targets
    from pincal.paper.methods import PaperCalibration, calibrate_paper
    from pincal.paper.ml_estimator import MLCalibration, MLSettings, calibrate_ml
    from pincal.paper.noise_limit import PredictedErrors, predicted_errors
    from pincal.planning.camera_plan import CameraPlanSettings
    from pincal.planning.planner import PlanSettings
    from pincal.report.html import render_html, write_html
    from pincal.simulation.paper import (
        SimulatedExperiment,
        SimulationSettings,
        simulate_experiment,
    )
    from pincal.workflows.calibration import CalibrationRun, calibrate_files
    from pincal.workflows.camera_calibration import (
        CameraCalibrateSettings,
        CameraCalibrationRun,
        calibrate_camera_files,
    )
    from pincal.workflows.camera_diagnosis import CameraDiagnoseRun, CameraDiagnoseSettings, diagnose_camera_files
    from pincal.workflows.camera_evaluation import CameraEvaluateSettings, CameraEvaluation, evaluate_camera_files
    from pincal.workflows.camera_plan import CameraPlanInputs, CameraPlanRun, camera_plan_files
    from pincal.workflows.camera_simulation import CameraSimulation, CameraSimulationSettings, simulate_camera_files
    from pincal.workflows.detection import DetectRun, DetectSettings, detect_files
    from pincal.workflows.diagnosis import DiagnoseOutputs, DiagnoseRun, diagnose_files
    from pincal.workflows.evaluation import Evaluation, SessionEvaluation, evaluate_files
    from pincal.workflows.evaluation_outputs import (
        EvaluateOutputs,
        EvaluateRun,
        ThresholdFailure,
        evaluate_and_write,
    )
    from pincal.workflows.extract import BagRead, CutFailed, ImageExtraction, NoPostures, extract_file, extract_images
    from pincal.workflows.fixture import (
        FixtureEvaluation,
        FixtureRun,
        calibrate_fixture_files,
        evaluate_fixture_files,
    )
    from pincal.workflows.preparation import PlanInputs, PlanRun, plan_files, urdf_from_dh_file
    from pincal.workflows.report_page import report_file
    from pincal.workflows.settings import CalibrateSettings, DiagnoseSettings, EvaluateSettings
    from pincal.workflows.simulation import simulate_to_directory
    from pincal.workflows.tree_calibration import TreeCalibrationRun, calibrate_tree_files
    from pincal.workflows.tree_diagnosis import TreeDiagnoseRun, diagnose_tree_files
    from pincal.workflows.tree_evaluation import TreeEvaluation, evaluate_tree_files

__all__ = [
    "__version__",
    "CalibrationError",
    "ChainCalibration",
    "ChainFitOptions",
    "JointOffsets",
    "MLCalibration",
    "MLSettings",
    "PlacementErrors",
    "PredictedErrors",
    "calibrate_chain",
    "calibrate_fixture",
    "choose_fixture_level",
    "choose_level",
    "LevelChoice",
    "fixture_metrics",
    "FixtureMetrics",
    "Fixture",
    "FixtureCalibration",
    "FixtureData",
    "read_fixture",
    "read_fixture_data",
    "calibrate_ml",
    "predicted_errors",
    "ChainPoses",
    "DHDeviations",
    "DHParameterSet",
    "DHRobot",
    "dh_robot_from_urdf",
    "read_dh_csv",
    "render_html",
    "write_html",
    "urdf_from_dh",
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
    "RowCorrections",
    "SimulatedExperiment",
    "SimulationSettings",
    "TABLE2_LARGE",
    "TABLE2_SMALL",
    "calibrate_paper",
    "pose_errors",
    "pose_from_xyz_rpy",
    "read_measurements",
    "read_sessions",
    "register_orientations",
    "register_points",
    "simulate_experiment",
    "write_measurements",
    "xyz_rpy_from_pose",
    "read_bag",
    "extract_postures",
    "PlateauSettings",
    "CalibrateSettings",
    "DiagnoseSettings",
    "EvaluateSettings",
    "CalibrationRun",
    "calibrate_files",
    "DiagnoseOutputs",
    "DiagnoseRun",
    "diagnose_files",
    "Evaluation",
    "SessionEvaluation",
    "evaluate_files",
    "EvaluateOutputs",
    "EvaluateRun",
    "ThresholdFailure",
    "evaluate_and_write",
    "report_file",
    "FixtureRun",
    "FixtureEvaluation",
    "calibrate_fixture_files",
    "evaluate_fixture_files",
    "PlanInputs",
    "PlanRun",
    "PlanSettings",
    "plan_files",
    "urdf_from_dh_file",
    "CameraPlanSettings",
    "CameraPlanInputs",
    "CameraPlanRun",
    "camera_plan_files",
    "BagRead",
    "extract_file",
    "NoPostures",
    "CutFailed",
    "ImageExtraction",
    "extract_images",
    "CharucoSpec",
    "parse_board",
    "DetectSettings",
    "DetectRun",
    "detect_files",
    "CameraCalibrateSettings",
    "CameraCalibrationRun",
    "calibrate_camera_files",
    "CameraEvaluateSettings",
    "CameraEvaluation",
    "evaluate_camera_files",
    "CameraSimulationSettings",
    "CameraSimulation",
    "simulate_camera_files",
    "CameraDiagnoseSettings",
    "CameraDiagnoseRun",
    "diagnose_camera_files",
    "CameraDiagnosis",
    "diagnose_camera",
    "simulate_to_directory",
    "KinematicTree",
    "TargetSpec",
    "parse_targets",
    "TreeCalibration",
    "calibrate_tree",
    "TreeCalibrationRun",
    "calibrate_tree_files",
    "TreeEvaluation",
    "evaluate_tree_files",
    "TreeDiagnoseRun",
    "diagnose_tree_files",
    "TreeDiagnosis",
    "diagnose_tree",
]

_ON_FIRST_USE = {name: module for module, names in _DEFINED_IN.items() for name in names}


def __getattr__(name: str) -> object:
    if name in _ON_FIRST_USE:
        import importlib

        value = getattr(importlib.import_module(_ON_FIRST_USE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'pincal' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
