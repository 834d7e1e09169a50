"""FANUC TP in ASCII form (``.ls``; a long program calls part programs ``<stem>_<k>.ls``):
:mod:`roboisf.programs.fanuc`."""

from __future__ import annotations

from roboisf.programs.registry import ProgramFormat, lazy, register, robot_writer

_MODULE = "roboisf.programs.fanuc"

register(
    ProgramFormat(
        name="fanuc",
        suffixes=(".ls",),
        kind="robot",
        label="FANUC TP",
        suffix_required=True,
        rank=40,
        write=robot_writer(_MODULE, "write_fanuc"),
        read=lazy(_MODULE, "read_fanuc"),
        check_name=lazy(_MODULE, "check_program_name"),
    )
)
