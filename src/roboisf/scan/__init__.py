"""Scans vs nominal: read point clouds and meshes, register them to the nominal part, signed
deviation vectors per scan point, per toolpath point, per depth, per angle and per arc length
along a lap.

The names below load their module on first use (PEP 562), so that the file-format registry
(which lists the scan formats of :mod:`roboisf.scan.formats`) and the commands that only read a
scan do not import scipy and numba.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.scan.compare import (
        CompareOptions,
        PreparedScan,
        ScanComparison,
        compare_scan,
        finish_scan,
        part_size,
        prepare_scan,
    )
    from roboisf.scan.deviation import (
        FootDeviations,
        PointDeviations,
        ToolpathDeviations,
        default_rim_band,
        foot_deviations,
        point_deviations,
        select_wall,
        statistical_outliers,
        toolpath_deviations,
    )
    from roboisf.scan.output import (
        POINT_COLUMNS,
        TOOLPATH_COLUMNS,
        point_table,
        toolpath_table,
        write_summary_json,
        write_table,
    )
    from roboisf.scan.readers import (
        ScanCloud,
        check_units,
        read_mesh,
        read_scan,
        sample_faces,
        scan_formats,
    )
    from roboisf.scan.registration import METHODS, Registration, register
    from roboisf.scan.summary import (
        DeviationStats,
        by_angle,
        by_arc_length,
        by_depth,
        deviation_stats,
        lap_arc_length,
        normal_deviation_stats,
        resultant_mean_deviation,
    )
    from roboisf.scan.symmetry import SymmetryEstimate, detect_symmetry, part_symmetry
    from roboisf.scan.synthetic import OffsetField, SyntheticScan, radial_offset, synthetic_scan
    from roboisf.scan.writers import write_ply

_WHERE = {
    "compare": (
        "CompareOptions",
        "PreparedScan",
        "ScanComparison",
        "compare_scan",
        "finish_scan",
        "part_size",
        "prepare_scan",
    ),
    "deviation": (
        "FootDeviations",
        "PointDeviations",
        "ToolpathDeviations",
        "default_rim_band",
        "foot_deviations",
        "point_deviations",
        "select_wall",
        "statistical_outliers",
        "toolpath_deviations",
    ),
    "output": (
        "POINT_COLUMNS",
        "TOOLPATH_COLUMNS",
        "point_table",
        "toolpath_table",
        "write_summary_json",
        "write_table",
    ),
    "readers": (
        "ScanCloud",
        "check_units",
        "read_mesh",
        "read_scan",
        "sample_faces",
        "scan_formats",
    ),
    "registration": (
        "METHODS",
        "Registration",
        "register",
    ),
    "summary": (
        "DeviationStats",
        "by_angle",
        "by_arc_length",
        "by_depth",
        "deviation_stats",
        "lap_arc_length",
        "normal_deviation_stats",
        "resultant_mean_deviation",
    ),
    "symmetry": (
        "SymmetryEstimate",
        "detect_symmetry",
        "part_symmetry",
    ),
    "synthetic": (
        "OffsetField",
        "SyntheticScan",
        "radial_offset",
        "synthetic_scan",
    ),
    "writers": ("write_ply",),
}
__all__ = [
    "METHODS",
    "POINT_COLUMNS",
    "TOOLPATH_COLUMNS",
    "CompareOptions",
    "DeviationStats",
    "FootDeviations",
    "OffsetField",
    "PointDeviations",
    "PreparedScan",
    "Registration",
    "ScanCloud",
    "ScanComparison",
    "SymmetryEstimate",
    "SyntheticScan",
    "ToolpathDeviations",
    "by_angle",
    "by_arc_length",
    "by_depth",
    "check_units",
    "compare_scan",
    "default_rim_band",
    "detect_symmetry",
    "deviation_stats",
    "finish_scan",
    "foot_deviations",
    "lap_arc_length",
    "normal_deviation_stats",
    "part_size",
    "part_symmetry",
    "point_deviations",
    "point_table",
    "prepare_scan",
    "radial_offset",
    "read_mesh",
    "read_scan",
    "register",
    "resultant_mean_deviation",
    "sample_faces",
    "scan_formats",
    "select_wall",
    "statistical_outliers",
    "synthetic_scan",
    "toolpath_deviations",
    "toolpath_table",
    "write_ply",
    "write_summary_json",
    "write_table",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
