"""Study folders: ``study.toml`` (part, tool, holder, robot, units, runs) validated as a whole.

Names load their module on first use (:mod:`roboisf._lazy`): ``roboisf.study.locate`` — the
check a command runs on its STUDY argument before anything heavy — imports no numeric library.
"""

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.study.locate import STUDY_FILE, read_study_toml, study_file
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
    "STUDY_FILE",
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
    "read_study_toml",
    "study_file",
]

_WHERE = {
    "locate": ("STUDY_FILE", "read_study_toml", "study_file"),
    "spec": (
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
    ),
}
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
