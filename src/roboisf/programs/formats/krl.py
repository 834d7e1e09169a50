"""KUKA KRL (``.src`` and its data list ``.dat``): :mod:`roboisf.programs.krl`."""

from __future__ import annotations

from roboisf.programs.registry import ProgramFormat, lazy, register, robot_writer

_MODULE = "roboisf.programs.krl"

register(
    ProgramFormat(
        name="krl",
        suffixes=(".src",),
        kind="robot",
        label="KRL",
        companions=(".dat",),
        suffix_required=True,
        rank=30,
        write=robot_writer(_MODULE, "write_krl"),
        read=lazy(_MODULE, "read_krl"),
        check_name=lazy(_MODULE, "krl_name"),
    )
)
