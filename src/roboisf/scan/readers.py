"""Scan readers: PLY, PCD, XYZ/CSV/TXT point lists, STL/OBJ meshes → points in m.

Library choices (one per format, for memory and robustness):

* **PLY** — ``plyfile``: reads ascii and binary (both endians); binary files are memory-mapped
  (``mmap``), so a 3 M point file is not loaded twice — the only copy made is the (N, 3)
  float64 array of coordinates. Open3D would copy into its own tensor and drop extra fields.
* **PCD** — a small reader here: a PCD file is a text header plus one raw array (``DATA ascii``
  or ``binary``); ``numpy.memmap`` / ``pandas.read_csv`` read it without extra copies. The
  ``binary_compressed`` variant (LZF) needs Open3D or PCL: re-save it as binary.
* **XYZ/CSV/TXT** — ``pandas.read_csv`` (C engine): the fastest robust text parser at hand; the
  delimiter (comma, semicolon, tab or spaces) and an optional header (``x,y,z[,nx,ny,nz]``) are
  detected.
  A Leica ``.pts`` count line (one integer before the points) is checked against the number of
  points read, and its intensity/RGB columns are ignored; a decimal comma (``1,5;2,5;3,5`` or
  ``1,5 2,5 3,5``) is detected from the first data row.
* **E57** — ``pye57`` (optional extra ``roboisf[scan-formats]``): every scan in the file, with
  its pose applied (points in the file's common frame). E57 coordinates are metres by the
  standard (ASTM E2807), so the declared ``unit`` does not apply and the cloud is in m.
* **LAS/LAZ** — ``laspy`` (same extra, with its ``lazrs`` backend for LAZ): the scaled
  coordinates, in the declared ``unit`` (LAS carries no length unit of its own).
* **STL/OBJ** (and PLY meshes as nominals) — ``trimesh``: ascii and binary STL, OBJ with any
  polygons (triangulated), merged vertices. Scans exported as meshes give their vertices, or
  ``sample`` points drawn uniformly over the faces.

Units: the file's numbers are in ``unit`` (default mm) and converted to m here, the only place.
"""

from __future__ import annotations

import math
import re
import sys
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.formats import file_formats, find_file_format
from roboisf.io.text import read_text
from roboisf.io.units import LENGTH_UNITS, to_si
from roboisf.parts.mesh import read_mesh
from roboisf.scan.formatspec import ScanSpec

__all__ = [
    "ScanCloud",
    "check_units",
    "read_e57_points",
    "read_las_points",
    "read_mesh",
    "read_mesh_points",
    "read_pcd_points",
    "read_ply_points",
    "read_scan",
    "read_xyz_points",
    "sample_faces",
    "scan_formats",
]

F64 = NDArray[np.float64]


def scan_formats() -> dict[str, str]:
    """Suffix (lower case, with the dot) → the registered scan format that reads it
    (:mod:`roboisf.formats`; one module per format in :mod:`roboisf.scan.formats`)."""
    return {sfx: f.name for f in file_formats("scan") for sfx in f.suffixes}


@dataclass
class ScanCloud:
    """A scan as points in the scanner's frame, SI.

    Attributes
    ----------
    points : (N, 3) float, m
    normals : (N, 3) float or None — unit normals if the file has them
    source : str — the file it was read from
    unit : str — the unit the file's numbers were in

    :meth:`take_points` hands the points over to one consumer (:func:`~roboisf.scan.compare_scan`
    with ``consume=True``), so they can be freed while the caller still holds the cloud.
    """

    points: F64
    normals: F64 | None
    source: str
    unit: str = "mm"

    def __post_init__(self) -> None:
        check_finite(self.points, self.source)
        if self.points.shape[0] == 0:
            raise InputError("scan has no points", file=self.source)
        self._n = int(self.points.shape[0])
        # the array read_scan made (its own: nobody else holds it), while it is still `points`
        self._made: weakref.ref[F64] | None = None

    @property
    def n_points(self) -> int:
        """Points read (still the file's count after :meth:`take_points`)."""
        return self._n

    def take_points(self) -> F64:
        """The (N, 3) points [m], handed over: the cloud keeps an empty (0, 3) array, so the
        only reference left is the caller's (a 10 M-point scan: 240 MB freed as soon as the
        consumer drops them). Raises :class:`InputError` if they were already taken."""
        pts = self.points
        if pts.shape[0] == 0:
            raise InputError("the scan's points were already taken", file=self.source)
        self.points = np.empty((0, 3))
        return pts

    def take_own_points(self) -> tuple[F64, bool]:
        """:meth:`take_points`, and whether they are the array :func:`read_scan` made for this
        cloud (float64, C-contiguous) and nothing but the cloud references it: the consumer
        may then overwrite it (:func:`~roboisf.scan.prepare_scan` puts the scan into the work
        frame in place). False for points a caller gave, put in or kept a reference to."""
        made = self._made() if self._made is not None else None
        # held by `points` and `made` (and getrefcount's argument) only: no caller kept it
        own = made is not None and made is self.points and sys.getrefcount(made) == 3
        self._made = None
        del made
        return self.take_points(), own


def check_finite(points: F64, source: str | Path | None) -> None:
    """Raise an :class:`InputError` naming ``source`` if ``points`` (N, 3) has NaN/inf."""
    # the whole array at once first (contiguous: 2 ms on a 2 M-point scan); the per-row
    # reduction below, along a strided axis (30 ms), only to name the bad points
    if np.isfinite(points).all():
        return
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(
            f"{int(bad.sum())} point(s) have NaN or inf coordinates (first: point {i}); "
            "remove them or export the scan without invalid points",
            file=source,
        )


def read_scan(
    path: str | Path,
    *,
    unit: str = "mm",
    sample: int | None = None,
    seed: int = 0,
) -> ScanCloud:
    """Read a scan file (PLY, PCD, XYZ/CSV/TXT, STL/OBJ) into points in m.

    Parameters
    ----------
    path : the file; its format is chosen by extension (:func:`scan_formats`: the registered
        scan formats)
    unit : the length unit of the file's numbers (``mm`` default, ``m``, ``um``, ``cm``, ``in``)
    sample : for mesh files (STL/OBJ, or a PLY with faces when given): draw this many points
        uniformly over the faces instead of returning the vertices
    seed : random seed of the face sampling
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("scan file not found", file=path)
    scale = to_si(unit, "length", file=path, field="unit")
    fmt = find_file_format(path, "scan")
    if fmt is None or fmt.reader is None:
        raise InputError(
            f"unknown scan format {path.suffix!r}; expected one of {', '.join(scan_formats())}",
            file=path,
        )
    if path.stat().st_size == 0:
        raise InputError("file is empty", file=path)
    normals: F64 | None
    pts, normals = fmt.reader(path, sample, seed)
    if isinstance(fmt.spec, ScanSpec):  # the length unit the format fixes (E57: metres)
        scale, unit = to_si(fmt.spec.unit, "length"), fmt.spec.unit
    if pts.shape[0] == 0:
        raise InputError("scan has no points", file=path)
    pts *= scale  # in place: pts is our own float64 copy; NaN/inf refused by ScanCloud
    if normals is not None:
        nn = np.linalg.norm(normals, axis=1, keepdims=True)
        ok = np.isfinite(nn[:, 0]) & (nn[:, 0] > 0)
        normals = np.where(ok[:, None], normals / np.where(ok[:, None], nn, 1.0), 0.0)
    cloud = ScanCloud(pts, normals, str(path), unit)
    if pts.dtype == np.float64 and pts.flags.c_contiguous and pts.flags.writeable:
        cloud._made = weakref.ref(pts)  # ours: scaled in place above
    return cloud


def read_mesh_points(path: Path, sample: int | None, seed: int) -> tuple[F64, F64 | None]:
    """A mesh's vertices, or ``sample`` points drawn uniformly over its faces (with their
    normals); in the file's unit."""
    V, F = read_mesh(path, unit="m")
    if sample:
        return sample_faces(V, F, sample, seed)
    return V, None


def _xyz_normals(rec: np.ndarray, normal_names: tuple[str, str, str]) -> tuple[F64, F64 | None]:
    """Copy x, y, z (and the normals, if all three fields exist) of a structured (memory-mapped)
    record array into (N, 3) float64 arrays — the only copies the readers make."""
    names = rec.dtype.names or ()
    pts = np.empty((len(rec), 3))
    # a signalling NaN in the file warns on the cast; NaN/inf are refused by check_finite
    with np.errstate(invalid="ignore"):
        for j, c in enumerate("xyz"):
            pts[:, j] = rec[c]
        normals = None
        if all(c in names for c in normal_names):
            normals = np.empty((len(rec), 3))
            for j, c in enumerate(normal_names):
                normals[:, j] = rec[c]
    return pts, normals


# -- PLY ----------------------------------------------------------------------------------------
#: PLY scalar types (the spec's names, their sized aliases and plyfile's numpy codes) → bytes.
_PLY_TYPES = {
    "char": 1, "int8": 1, "i1": 1, "uchar": 1, "uint8": 1, "u1": 1,
    "short": 2, "int16": 2, "i2": 2, "ushort": 2, "uint16": 2, "u2": 2,
    "int": 4, "int32": 4, "i4": 4, "uint": 4, "uint32": 4, "u4": 4,
    "float": 4, "float32": 4, "f4": 4, "double": 8, "float64": 8, "f8": 8,
}  # fmt: skip
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
#: Longest PLY header read (a real header is a few hundred bytes).
_PLY_MAX_HEADER = 1 << 20


@dataclass
class _PlyElement:
    """An ``element`` of a PLY header: its smallest row (list properties empty) in bytes."""

    name: str
    count: int
    line: int
    row_bytes: int = 0
    n_props: int = 0


def check_ply_header(path: Path) -> None:
    """Validate a PLY header before ``plyfile``/``numpy.memmap`` see it.

    Checks the magic line, the format, every ``element`` count (a non-negative integer),
    every ``property`` type, and that the counts fit in the file: a binary body without list
    properties must hold exactly ``Σ count × row size`` bytes (at least), a body with lists or
    in ascii at least the smallest possible row per element. A negative or absurd count would
    otherwise reach numpy as a memory map of negative size (the process dies with SIGFPE) or an
    allocation of petabytes.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(min(size, _PLY_MAX_HEADER))
    end = re.search(rb"(^|\n)end_header[ \t]*\r?\n", head)
    if not head.startswith(b"ply") or head[3:4] not in (b"\n", b"\r"):
        raise InputError("not a PLY file (the first line must be 'ply')", file=path, line=1)
    if end is None:
        raise InputError("PLY header has no 'end_header' line (truncated file?)", file=path)
    body = size - end.end()
    fmt = None
    elements: list[_PlyElement] = []
    text = head[: end.start()].decode("ascii", errors="replace").splitlines()
    for i, raw in enumerate(text[1:], start=2):
        tok = raw.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            if len(tok) != 3 or tok[1] not in _PLY_FORMATS:
                raise InputError(
                    f"bad PLY format line {raw.strip()!r}; expected 'format "
                    f"{{{'|'.join(_PLY_FORMATS)}}} 1.0'",
                    file=path,
                    line=i,
                )
            fmt = tok[1]
        elif tok[0] == "element":
            if len(tok) != 3 or not re.fullmatch(r"\d{1,19}", tok[2]):
                raise InputError(
                    f"bad PLY element line {raw.strip()!r}; expected 'element NAME COUNT' with "
                    "COUNT a non-negative integer",
                    file=path,
                    line=i,
                )
            elements.append(_PlyElement(tok[1], int(tok[2]), i))
        elif tok[0] == "property":
            if not elements:
                raise InputError("PLY property before any element", file=path, line=i)
            el = elements[-1]
            if len(tok) == 5 and tok[1] == "list":
                if tok[2] not in _PLY_TYPES or tok[3] not in _PLY_TYPES or tok[2][0] == "f":
                    raise InputError(
                        f"bad PLY list property {raw.strip()!r}; expected 'property list "
                        "<integer type> <type> NAME'",
                        file=path,
                        line=i,
                    )
                el.row_bytes += _PLY_TYPES[tok[2]]
            elif len(tok) == 3 and tok[1] in _PLY_TYPES:
                el.row_bytes += _PLY_TYPES[tok[1]]
            else:
                raise InputError(
                    f"bad PLY property {raw.strip()!r}; expected 'property TYPE NAME' with TYPE "
                    "one of char uchar short ushort int uint float double",
                    file=path,
                    line=i,
                )
            el.n_props += 1
        else:
            raise InputError(f"unknown PLY header line {raw.strip()!r}", file=path, line=i)
    if fmt is None:
        raise InputError("PLY header has no 'format' line", file=path)
    need = 0
    for el in elements:
        name, count, line = el.name, el.count, el.line
        if el.n_props == 0 and count > 0:
            raise InputError(f"PLY element {name!r} has no properties", file=path, line=line)
        # smallest possible row: binary → its bytes (lists empty), ascii → a digit + a separator
        # per property
        need += count * (el.row_bytes if fmt != "ascii" else 2 * el.n_props)
        if need > body:
            raise InputError(
                f"PLY element {name!r} declares {count} rows, which need at least {need} bytes "
                f"of data, but the file has {body} after the header (truncated file or a wrong "
                "count)",
                file=path,
                line=line,
            )


def read_ply_points(path: Path, sample: int | None, seed: int) -> tuple[F64, F64 | None]:
    from plyfile import PlyData

    check_ply_header(path)
    try:
        with open(path, "rb") as fh:
            ply = PlyData.read(fh, mmap="r")
            if "vertex" not in ply:
                raise InputError("PLY has no 'vertex' element", file=path)
            v = ply["vertex"].data
            names = v.dtype.names or ()
            for c in ("x", "y", "z"):
                if c not in names:
                    raise InputError(f"PLY vertex has no {c!r} property", file=path)
            pts, normals = _xyz_normals(v, ("nx", "ny", "nz"))
            if sample and "face" in ply:
                F = _ply_faces(ply["face"].data, path)
                del v, ply
                return sample_faces(pts, F, sample, seed)
            del v, ply
    except InputError:
        raise
    except Exception as e:  # plyfile's parse errors, short reads, bad headers
        raise _ply_parse_error(path, e) from None
    return pts, normals


def _ply_parse_error(path: Path, e: Exception) -> InputError:
    """The error for a PLY that ``plyfile`` could not parse. In an ascii PLY a bad row of the
    first element (the vertices) is named by its line (header lines + row + 1), and a bad cell
    is not called a truncation: "row 100: property 'x': malformed input; the file may be
    truncated" sent the user to the end of a file whose line 109 held a word."""
    from plyfile import PlyElementParseError

    generic = InputError(
        f"not a readable PLY file ({type(e).__name__}: {e}); the file may be truncated",
        file=path,
    )
    if not isinstance(e, PlyElementParseError) or e.element is None or e.row is None:
        return generic
    with open(path, "rb") as fh:
        head = fh.read(_PLY_MAX_HEADER)
    end = head.find(b"end_header")
    if end < 0:
        return generic
    header = head[:end].decode("ascii", errors="replace").splitlines()
    first = next((ln.split()[1] for ln in header if ln.split()[:1] == ["element"]), None)
    if not any(ln.split()[:2] == ["format", "ascii"] for ln in header) or first != e.element.name:
        return generic
    prop = f", property {e.prop.name!r}" if e.prop is not None else ""
    if "end-of-file" in e.message:
        return InputError(
            f"the PLY file ends after {e.row} {first} rows of the {e.element.count} its header "
            "declares (truncated file or a wrong count)",
            file=path,
        )
    return InputError(
        f"PLY {first} row {e.row}{prop}: {e.message} (a cell that is not a number, or a row with "
        "too few or too many values)",
        file=path,
        line=len(header) + 1 + e.row + 1,
    )


def _ply_faces(data: np.ndarray, path: Path) -> NDArray[np.int64]:
    name = next(
        (n for n in ("vertex_indices", "vertex_index") if n in (data.dtype.names or ())), None
    )
    if name is None:
        raise InputError("PLY face element has no vertex_indices", file=path)
    rows = [np.asarray(f, dtype=np.int64) for f in data[name]]
    tris = [np.stack([r[[0] * (len(r) - 2)], r[1:-1], r[2:]], axis=1) for r in rows if len(r) >= 3]
    if not tris:
        raise InputError("PLY has no faces with 3 or more vertices", file=path)
    return np.concatenate(tris)


# -- PCD ----------------------------------------------------------------------------------------
_PCD_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    ("I", 1): "i1",
    ("I", 2): "i2",
    ("I", 4): "i4",
    ("I", 8): "i8",
    ("U", 1): "u1",
    ("U", 2): "u2",
    ("U", 4): "u4",
    ("U", 8): "u8",
}


def _pcd_int(text: str) -> int:
    """A non-negative integer of a PCD header (at most 19 digits: no absurd counts)."""
    if not re.fullmatch(r"\d{1,19}", text):
        raise ValueError(text)
    return int(text)


def read_pcd_points(path: Path) -> tuple[F64, F64 | None]:
    header: dict[str, list[str]] = {}
    offset = 0
    with open(path, "rb") as fh:
        for line_no in range(1, 21):  # noqa: B007 - used after the loop
            raw = fh.readline()
            if not raw:
                raise InputError(
                    "PCD header ends before the DATA line (truncated file?)", file=path
                )
            offset += len(raw)
            text = raw.decode("ascii", errors="replace").strip()
            if not text or text.startswith("#"):
                continue
            key, *vals = text.split()
            header[key.upper()] = vals
            if key.upper() == "DATA":
                break
        else:
            raise InputError("no DATA line in the first 20 header lines; not a PCD file", file=path)
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS", "DATA"):
        if key not in header:
            raise InputError(f"PCD header has no {key} line", file=path, line=line_no)
    fields = header["FIELDS"]
    k = len(fields)
    count_text = header.get("COUNT", ["1"] * k)
    for key, vals in (("SIZE", header["SIZE"]), ("TYPE", header["TYPE"]), ("COUNT", count_text)):
        if len(vals) != k:
            raise InputError(
                f"PCD {key} has {len(vals)} entries but FIELDS has {k}", file=path, field=key
            )
    if len(set(fields)) != k:
        raise InputError(f"PCD FIELDS repeats a name: {' '.join(fields)}", file=path)
    if not header["DATA"] or len(header["POINTS"]) != 1:
        raise InputError("PCD DATA and POINTS need one value each", file=path)
    try:
        n = _pcd_int(header["POINTS"][0])
        count = [_pcd_int(c) for c in count_text]
        dtypes = [
            _PCD_TYPES[(t.upper(), int(s))]
            for t, s in zip(header["TYPE"], header["SIZE"], strict=True)
        ]
    except (KeyError, ValueError, IndexError):
        raise InputError(
            "PCD header has bad SIZE/TYPE/COUNT/POINTS values (TYPE F/I/U with SIZE 1/2/4/8, "
            "COUNT and POINTS non-negative integers)",
            file=path,
        ) from None
    if min(count, default=1) < 1:
        raise InputError("PCD COUNT entries must be ≥ 1", file=path, field="COUNT")
    for c in ("x", "y", "z"):
        if c not in fields:
            raise InputError(f"PCD has no field {c!r} (FIELDS {' '.join(fields)})", file=path)
    for c in ("x", "y", "z", "normal_x", "normal_y", "normal_z"):
        if c in fields and count[fields.index(c)] != 1:
            raise InputError(f"PCD field {c!r} must have COUNT 1", file=path, field="COUNT")
    mode = header["DATA"][0].lower()
    # column index of each field in the flat record
    col: dict[str, int] = {}
    j = 0
    for f, cnt in zip(fields, count, strict=True):
        col[f] = j
        j += cnt
    if mode == "ascii":
        import pandas as pd

        names = ("x", "y", "z", "normal_x", "normal_y", "normal_z")
        cols = [col[f] for f in names if f in col]
        if len(cols) not in (3, 6):
            cols = cols[:3]

        try:
            df = pd.read_csv(
                path,
                skiprows=line_no,
                header=None,
                sep=r"\s+",
                engine="c",
                usecols=cols,
                dtype=np.float64,
            )
        except Exception as e:
            raise InputError(f"PCD ascii data could not be parsed: {e}", file=path) from None
        arr = df[cols].to_numpy()  # x, y, z[, normals] whatever the file's field order
        if arr.shape[0] != n:
            raise InputError(
                f"PCD says POINTS {n} but has {arr.shape[0]} rows (truncated?)", file=path
            )
        pts = np.ascontiguousarray(arr[:, :3])
        normals = np.ascontiguousarray(arr[:, 3:6]) if arr.shape[1] >= 6 else None
        return pts, normals
    if mode != "binary":
        raise InputError(
            f"PCD DATA {mode} is not supported; re-save the cloud as 'binary' or 'ascii' "
            "(e.g. pcl_convert_pcd_ascii_binary, or Open3D write_point_cloud(compressed=False))",
            file=path,
        )
    dt = np.dtype(
        [
            (f"{f}", dtypes[i], (count[i],)) if count[i] > 1 else (f"{f}", dtypes[i])
            for i, f in enumerate(fields)
        ]
    )
    need = offset + n * dt.itemsize
    size = path.stat().st_size
    if size < need:
        raise InputError(
            f"PCD binary data is truncated: {n} points need {need} bytes, file has {size}",
            file=path,
        )
    rec = np.memmap(path, dtype=dt, mode="r", offset=offset, shape=(n,))
    out = _xyz_normals(rec, ("normal_x", "normal_y", "normal_z"))
    del rec
    return out


# -- XYZ / CSV / TXT ---------------------------------------------------------------------------
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf)$", re.IGNORECASE)


def read_xyz_points(path: Path) -> tuple[F64, F64 | None]:
    """x, y, z [and nx, ny, nz] of a point list, in the file's unit. UTF-8 with or without a
    byte-order mark (Excel's "CSV UTF-8" and many Windows exporters write one: it was read into
    the first header cell, and ``x,y,z`` refused as having no x column)."""
    import pandas as pd

    first = None
    skip = 0
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith(("#", "//")):
                first = line.strip()
                break
            skip += 1
    if first is None:
        raise InputError("point list has no data (only blank or comment lines)", file=path)
    count = None
    if re.fullmatch(r"\d+", first):
        # Leica PTS: the number of points on a line of its own, then x y z [i [r g b]]
        count = int(first)
        skip += 1
        first = None
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            for i, line in enumerate(fh):
                if i >= skip and line.strip():
                    first = line.strip()
                    break
                if i >= skip:
                    skip += 1
        if first is None:
            raise InputError(f"PTS count line says {count} points but none follow", file=path)
    pts_like = count is not None or path.suffix.lower() == ".pts"
    sep, decimal = _sniff_xyz(first)
    tokens = [t for t in re.split(sep, first.strip()) if t != ""]
    has_header = not all(_NUM.match(t.strip().replace(",", ".")) for t in tokens)
    names = [t.strip().lower() for t in tokens] if has_header else None
    if has_header:
        assert names is not None
        want = ["x", "y", "z"]
        if not all(c in names for c in want):
            raise InputError(
                f"header {first!r} has no x, y, z columns; "
                "expected 'x,y,z[,nx,ny,nz]' or no header",
                file=path,
                line=skip + 1,
            )
        ncols = [c for c in ("nx", "ny", "nz") if c in names]
        usecols = [names.index(c) for c in want + (ncols if len(ncols) == 3 else [])]
    else:
        if len(tokens) < 3:
            raise InputError(
                f"expected at least 3 columns x y z, got {len(tokens)}", file=path, line=skip + 1
            )
        usecols = list(range(6 if len(tokens) >= 6 and not pts_like else 3))
    if has_header and decimal == ".":
        # the header does not tell the decimal mark: the first data row does
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            rows = [ln for i, ln in enumerate(fh) if i > skip and ln.strip()][:1]
        if rows and sep != ",":
            decimal = _sniff_xyz(rows[0].strip())[1]
    try:
        df = pd.read_csv(
            path,
            sep=sep,
            decimal=decimal,
            header=None,
            skiprows=skip + (1 if has_header else 0),
            usecols=usecols,
            comment="#",
            dtype=np.float64,
            skip_blank_lines=True,
            engine="c",
            encoding="utf-8-sig",
        )
    except UnicodeDecodeError:
        read_text(path, what="point list")  # raises, naming the line and byte offset
        raise  # pragma: no cover - read_text raised above
    except ValueError as e:
        raise InputError(f"not a number in the point list: {e}", file=path) from None
    except Exception as e:
        raise InputError(f"could not parse the point list: {e}", file=path) from None
    arr = df[usecols].to_numpy()  # x, y, z[, nx, ny, nz] in that order
    if arr.shape[0] == 0:
        raise InputError("point list has a header but no data rows", file=path)
    if count is not None and arr.shape[0] != count:
        raise InputError(
            f"PTS count line says {count} points but {arr.shape[0]} were read (a file of "
            "several scans, each with its count line, is not supported: export one cloud)",
            file=path,
            line=1,
        )
    pts = np.ascontiguousarray(arr[:, :3])
    normals = np.ascontiguousarray(arr[:, 3:6]) if arr.shape[1] >= 6 else None
    return pts, normals


_DEC_COMMA = re.compile(r"^[+-]?\d+,\d*([eE][+-]?\d+)?$")


def _sniff_xyz(line: str) -> tuple[str, str]:
    """(separator regex/char, decimal mark) of a point-list row: ``;`` / tab / blanks with a
    decimal comma or point, or ``,`` with a decimal point."""
    for sep in (";", "\t", r"\s+", ","):
        toks = [t for t in re.split(sep, line.strip()) if t != ""]
        if len(toks) < 3:
            continue
        if all(_NUM.match(t.strip()) for t in toks):
            return sep, "."
        if sep != "," and all(_DEC_COMMA.match(t.strip()) or _NUM.match(t.strip()) for t in toks):
            return sep, ","
    if "," in line:
        return ",", "."
    if ";" in line:
        return ";", "."
    return r"\s+", "."


def _optional(module: str, what: str, path: Path) -> object:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(
            f"reading {what} needs the Python package {module!r}: "
            "pip install 'roboisf[scan-formats]'",
            file=path,
        ) from None


def read_e57_points(path: Path) -> F64:
    pye57: object = _optional("pye57", "E57 scans", path)
    try:
        e57 = pye57.E57(str(path))  # type: ignore[attr-defined]
        parts = []
        for i in range(e57.scan_count):
            d = e57.read_scan(i, ignore_missing_fields=True, transform=True)
            if "cartesianX" not in d:
                raise InputError(
                    f"scan {i} has no cartesian coordinates (spherical-only E57 is not "
                    "supported; export cartesian)",
                    file=path,
                )
            parts.append(np.column_stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]]))
    except InputError:
        raise
    except Exception as e:  # pye57 raises bare RuntimeError/ValueError on a bad file
        raise InputError(f"not a readable E57 file: {e}", file=path) from None
    if not parts:
        raise InputError("E57 file holds no scan", file=path)
    return np.ascontiguousarray(np.vstack(parts), dtype=np.float64)


def read_las_points(path: Path) -> F64:
    laspy: object = _optional("laspy", "LAS/LAZ scans", path)
    try:
        las = laspy.read(str(path))  # type: ignore[attr-defined]
    except Exception as e:  # laspy.LaspyException, or a missing LAZ backend
        msg = str(e)
        hint = (
            ' (LAZ needs a backend: pip install "roboisf[scan-formats]", which brings lazrs)'
            if "laz" in msg.lower()
            else ""
        )
        raise InputError(f"not a readable LAS/LAZ file: {msg}{hint}", file=path) from None
    return np.column_stack(
        [
            np.asarray(las.x, dtype=float),
            np.asarray(las.y, dtype=float),
            np.asarray(las.z, dtype=float),
        ]
    )


# -- meshes ---------------------------------------------------------------------------------------
def sample_faces(V: F64, F: NDArray[np.int64], n: int, seed: int = 0) -> tuple[F64, F64]:
    """``n`` points uniformly distributed over the triangles' area, and their face normals."""
    rng = np.random.default_rng(seed)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(b - a, c - a)
    area = np.linalg.norm(cr, axis=1)
    if not np.any(area > 0):
        raise InputError("mesh has no triangle with a non-zero area")
    f = rng.choice(F.shape[0], size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])
    return pts, cr[f] / area[f][:, None]


# -- plausibility ----------------------------------------------------------------------------------
def _extent(points: F64) -> tuple[F64, F64]:
    """Per-axis minimum and maximum of the points (N ≥ 1, 3): one compiled pass when numba is
    installed (``min(axis=0)`` reduces along a strided axis: ~10x slower on a 2 M-point scan),
    the same numbers."""
    X = np.asarray(points, dtype=float)
    if jit.ready("mesh") and X.ndim == 2 and X.shape[0] > 0 and X.shape[1] == 3:
        from roboisf.parts.mesh_kernel import bounds

        lo, hi = bounds(X, np.zeros(0, dtype=np.int64))
        return np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return X.min(axis=0), X.max(axis=0)


def check_units(
    points: F64,
    part_size: float,
    *,
    unit: str,
    source: str | Path | None,
    setting: tuple[str | Path, str] | None = None,
) -> None:
    """Refuse a scan whose extent is implausible for a part of ``part_size`` [m].

    The scan's largest bounding-box extent must lie within 1/20 .. 20 × the part's size; else
    the declared ``unit`` is almost surely wrong, and the error names the unit that would fit.
    ``setting``: the (file, key) where ``unit`` was set when that is not the ``--unit`` option
    (a study's ``runs.NAME.scan_unit``): the error names that file and key and how to set it.
    """
    lo, hi = _extent(points)
    extent = float(np.max(hi - lo))
    if part_size <= 0:
        return
    if not extent > 0:
        raise InputError(
            f"scan has zero extent: all {points.shape[0]} point(s) are at the same position "
            f"({', '.join(f'{v * 1e3:.6g}' for v in lo)} mm); expected a scan of the part "
            f"({part_size * 1e3:.4g} mm across)",
            file=source,
        )
    ratio = extent / part_size
    if 1 / 20 <= ratio <= 20:
        return
    factor = LENGTH_UNITS[unit.strip()]
    # the unit that brings the extent closest to the part size
    best = min(LENGTH_UNITS, key=lambda u: abs(math.log(ratio * LENGTH_UNITS[u] / factor)))
    # where the unit is set: the --unit option, or a study's key (file and field name that)
    option, file, field, what = "--unit", source, "unit", "scan"
    if setting is not None:
        file, field = setting
        option = field.rsplit(".", 1)[-1]
        if source is not None:  # named from the study's folder, as study.toml names it
            src, root = Path(source), Path(file).parent
            what = f"scan {src.relative_to(root) if src.is_relative_to(root) else src}"
    fmt = find_file_format(source, "scan") if source is not None else None
    if fmt is not None and isinstance(fmt.spec, ScanSpec):
        # a format that fixes its unit (E57: metres by the standard): --unit is not applied
        u = fmt.spec
        raise InputError(
            f"{what} extent is {extent * 1e3:.6g} mm, {ratio:.3g}× the part's size "
            f"({part_size * 1e3:.4g} mm); {fmt.label} coordinates are {u.unit_name} {u.why} "
            f"({option} does not apply), so the file's numbers look like {best!r}: re-export the "
            f"scan in {u.unit_name}, or check that the part and the scan are the same object",
            file=file,
            field=field,
        )
    if setting is not None:
        table = field.rsplit(".", 1)[0]
        fix = f'set {option} = "{best}" in [{table}]'
    else:
        fix = f"pass --unit {best}"
    raise InputError(
        f"{what} extent is {extent * 1e3:.6g} mm read as {unit!r}, {ratio:.3g}× the part's size "
        f"({part_size * 1e3:.4g} mm); the file is probably in {best!r} — {fix}",
        file=file,
        field=field,
    )
