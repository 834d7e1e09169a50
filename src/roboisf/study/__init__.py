"""Study folders: ``study.toml`` (part, tool, holder, robot, units, runs) validated as a whole."""

from roboisf.study.spec import (
    AnalysisSpec,
    ForceSensorSpec,
    HolderSpec,
    RobotSpec,
    RunSpec,
    Study,
    StudyError,
    ToolSpec,
    UnitsSpec,
    load_study,
    pose_to_transform,
)

__all__ = [
    "AnalysisSpec",
    "ForceSensorSpec",
    "HolderSpec",
    "RobotSpec",
    "RunSpec",
    "Study",
    "StudyError",
    "ToolSpec",
    "UnitsSpec",
    "load_study",
    "pose_to_transform",
]
