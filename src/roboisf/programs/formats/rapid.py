"""ABB RAPID module (``.mod``; a long program is a main module and part modules
``<stem>_<k>.mod``): :mod:`roboisf.programs.rapid`."""

from __future__ import annotations

from roboisf.programs.registry import ProgramFormat, lazy, register, robot_writer

_MODULE = "roboisf.programs.rapid"

register(
    ProgramFormat(
        name="rapid",
        suffixes=(".mod",),
        kind="robot",
        label="ABB RAPID",
        read_suffixes=(".modx",),
        rank=20,
        write=robot_writer(_MODULE, "write_rapid"),
        read=lazy(_MODULE, "read_rapid"),
        check_name=lazy(_MODULE, "module_name"),
    )
)
