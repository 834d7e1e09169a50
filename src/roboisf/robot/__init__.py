"""Robot elastostatics: kinematic models (OPW/DH presets, URDF), batched FK and Jacobians,
inverse kinematics along a toolpath, VJM compliance and deflection, joint-stiffness
identification. Conventions: ``docs/robot.md``.

The names below load their module on first use (PEP 562): reading a study, which checks a
robot preset's name, imports neither the identification's tables (pandas) nor the kernels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
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

_WHERE = {
    "identify": (
        "CalibrationData",
        "PoorExcitationWarning",
        "StiffnessIdentification",
        "identify_stiffness",
        "read_calibration_csv",
    ),
    "ik": (
        "IKResult",
        "SingularityWarning",
        "ik_toolpath",
        "opw_ik",
        "tool_poses",
    ),
    "kinematics": (
        "Chain",
        "OPWGeometry",
        "chain_from_dh",
        "chain_from_opw",
    ),
    "maps": (
        "StiffnessMap",
        "stiffness_map",
    ),
    "model": ("RobotModel",),
    "presets": (
        "list_robots",
        "load_robot",
        "load_stiffness",
        "robot_from_dict",
    ),
    "urdf": (
        "load_urdf",
        "to_urdf",
    ),
    "vjm": (
        "ComplianceStats",
        "Contributions",
        "compliance_stats",
        "deflection_contributions",
        "geometric_stiffness",
        "loaded_deflection",
        "rotate_6",
        "rotate_6x6",
        "tip_compliance",
        "vjm_batch",
    ),
}

__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
