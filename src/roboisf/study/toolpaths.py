"""A study run's toolpath: the run's file read as the study says (format, point, ball radius).

This is the study's hook into :mod:`roboisf.toolpath.importer`; it lives in ``study`` so that the
toolpath package does not need to know what a study is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf.errors import InputError
from roboisf.toolpath.importer import load_toolpath

if TYPE_CHECKING:
    from roboisf.parts.base import Part
    from roboisf.path.toolpath import Toolpath
    from roboisf.study.spec import RunSpec, Study

__all__ = ["study_toolpath"]


def study_toolpath(study: Study, run: RunSpec, part: Part) -> Toolpath:
    """The toolpath of ``run`` of ``study`` (:func:`load_toolpath` with the study's settings)."""
    if study.tool is None:  # pragma: no cover - load_study requires [tool]
        raise InputError("the study has no [tool] table", file=study.root / "study.toml")
    return load_toolpath(
        run.toolpath,
        part,
        study.tool.radius,
        fmt=getattr(run, "toolpath_format", "auto"),
        point=getattr(run, "toolpath_point", "tip"),
    )
