"""Robot elastostatics: kinematic models (OPW/DH presets, URDF), batched FK and Jacobians,
inverse kinematics along a toolpath, VJM compliance and deflection, joint-stiffness
identification. Conventions: ``docs/robot.md``."""

from roboisf.robot.identify import (
    CalibrationData,
    PoorExcitationWarning,
    StiffnessIdentification,
    identify_stiffness,
    read_calibration_csv,
)
from roboisf.robot.ik import IKResult, SingularityWarning, ik_toolpath, opw_ik, tool_poses
from roboisf.robot.kinematics import Chain, OPWGeometry, chain_from_dh, chain_from_opw
from roboisf.robot.maps import StiffnessMap, stiffness_map
from roboisf.robot.model import RobotModel
from roboisf.robot.presets import list_robots, load_robot, load_stiffness, robot_from_dict
from roboisf.robot.urdf import load_urdf, to_urdf
from roboisf.robot.vjm import (
    ComplianceStats,
    Contributions,
    compliance_stats,
    deflection_contributions,
    geometric_stiffness,
    loaded_deflection,
    rotate_6,
    rotate_6x6,
    tip_compliance,
    vjm_batch,
)

__all__ = [
    "CalibrationData",
    "Chain",
    "ComplianceStats",
    "Contributions",
    "IKResult",
    "OPWGeometry",
    "PoorExcitationWarning",
    "RobotModel",
    "SingularityWarning",
    "StiffnessIdentification",
    "StiffnessMap",
    "chain_from_dh",
    "chain_from_opw",
    "compliance_stats",
    "deflection_contributions",
    "geometric_stiffness",
    "identify_stiffness",
    "ik_toolpath",
    "list_robots",
    "load_robot",
    "load_stiffness",
    "load_urdf",
    "loaded_deflection",
    "opw_ik",
    "read_calibration_csv",
    "robot_from_dict",
    "rotate_6",
    "rotate_6x6",
    "stiffness_map",
    "tip_compliance",
    "to_urdf",
    "tool_poses",
    "vjm_batch",
]
