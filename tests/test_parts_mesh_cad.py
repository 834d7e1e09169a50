"""Parts from CAD and mesh files: STEP tessellated with gmsh OCC to a stated tolerance (checked
against the analytic cone it was made from), and the `roboisf part pyramid|mesh` commands."""

import math

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.parts import Cone, MeshPart, Pyramid, load_part

R0, DEPTH, ALPHA = 40.0, 30.0, 60.0  # mm, mm, deg


def cone_step(path):
    """A STEP shell of a truncated cone (wall + flat bottom, no top disc), made with gmsh's OCC
    kernel: opening radius R0 at z = 0, wall angle ALPHA, depth DEPTH (mm)."""
    import gmsh

    r1 = R0 - DEPTH / math.tan(math.radians(ALPHA))
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cone")
        v = gmsh.model.occ.addCone(0, 0, 0, 0, 0, -DEPTH, R0, r1)
        gmsh.model.occ.synchronize()
        faces = gmsh.model.getBoundary([(3, v)], oriented=False)
        # the top disc: a face whose bounding box is flat at z = 0 (OCC pads boxes by ~1e-7)
        top = [f for f in faces if abs(gmsh.model.getBoundingBox(*f)[2]) < 1e-3]
        assert len(top) == 1
        gmsh.model.occ.remove([(3, v)])
        gmsh.model.occ.remove(top)
        gmsh.model.occ.synchronize()
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def triangle_samples(mesh: MeshPart, n=6):
    """Points on every triangle (a barycentric grid, vertices excluded)."""
    V, F = mesh.vertices, mesh.faces
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = (i + j <= n) & ~(((i == 0) & (j == 0)) | ((i == n) & (j == 0)) | ((i == 0) & (j == n)))
    u, v = i[keep] / n, j[keep] / n
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    P = a[:, None] + u[None, :, None] * (b - a)[:, None] + v[None, :, None] * (c - a)[:, None]
    return P.reshape(-1, 3)


@pytest.mark.parametrize("tol_mm", [0.05, 0.01])
def test_step_cone_tessellated_within_tolerance(tmp_path, tol_mm):
    step = cone_step(tmp_path / "cone.step")
    mesh = MeshPart.from_file(step, tolerance=tol_mm * 1e-3)
    cone = Cone(2 * R0 * 1e-3, math.radians(ALPHA), DEPTH * 1e-3, flange_width=0.0)
    # every vertex on the analytic cone, every point of every triangle within the tolerance
    assert np.abs(cone.closest_point(mesh.vertices).distance).max() < 1e-9
    dev = np.abs(cone.closest_point(triangle_samples(mesh)).distance).max()
    assert dev <= tol_mm * 1e-3
    # and not trivially: the chordal error is of the order of the tolerance
    assert dev > tol_mm * 1e-3 / 10
    assert mesh.depth == pytest.approx(DEPTH * 1e-3, abs=1e-9)
    assert mesh.tolerance == tol_mm * 1e-3


def test_part_mesh_command_and_round_trip(tmp_path):
    step = cone_step(tmp_path / "cad" / "cone.step") if (tmp_path / "cad").mkdir() is None else 0
    toml = tmp_path / "parts" / "cone.toml"
    toml.parent.mkdir()
    assert main(["part", "mesh", str(step), "--tolerance", "0.02", "-o", str(toml)]) == 0
    text = toml.read_text()
    assert 'file = "../cad/cone.step"' in text and "tolerance = 0.02" in text
    part = load_part(toml)
    assert isinstance(part, MeshPart) and part.tolerance == pytest.approx(0.02e-3)
    assert part.depth == pytest.approx(DEPTH * 1e-3, abs=1e-9)
    # a STL with a unit other than mm keeps its unit in the TOML
    import trimesh

    stl = tmp_path / "cad" / "tri.stl"
    trimesh.Trimesh([[0, 0, 0], [0.05, 0, 0], [0, 0.05, -0.01]], [[0, 1, 2]], process=False).export(
        stl
    )
    toml2 = tmp_path / "parts" / "tri.toml"
    assert main(["part", "mesh", str(stl), "--unit", "m", "-o", str(toml2)]) == 0
    assert load_part(toml2).depth == pytest.approx(0.01)


def test_part_mesh_errors(tmp_path, capsys):
    assert main(["part", "mesh", str(tmp_path / "none.step"), "-o", str(tmp_path / "a.toml")]) == 2
    assert not (tmp_path / "a.toml").exists()
    bad = tmp_path / "bad.step"
    bad.write_text("ISO-10303-21; this is not a step file")
    assert main(["part", "mesh", str(bad), "-o", str(tmp_path / "b.toml")]) == 2
    assert not (tmp_path / "b.toml").exists()
    err = capsys.readouterr().err
    assert "bad.step" in err and "Traceback" not in err
    with pytest.raises(InputError, match="unit"):
        MeshPart.from_file(cone_step(tmp_path / "c.step"), unit="m")


def test_part_pyramid_command(tmp_path):
    toml = tmp_path / "pyr.toml"
    args = ["--top-length", "120", "--top-width", "90", "--wall-angle", "55", "--depth", "30"]
    assert main(["part", "pyramid", *args, "--corner-radius", "5", "-o", str(toml)]) == 0
    p = load_part(toml)
    assert p == Pyramid(0.12, 0.09, math.radians(55), 0.03, corner_radius=0.005)
    assert p.symmetry.order == 2
    # two wall angles need sharp corners: exit 2, one line, no file
    bad = tmp_path / "bad.toml"
    assert main(["part", "pyramid", *args, "--wall-angle-y", "50", "-o", str(bad)]) == 2
    assert not bad.exists()
    assert (
        main(
            [
                "part",
                "pyramid",
                *args,
                "--wall-angle-y",
                "50",
                "--corner-radius",
                "0",
                "-o",
                str(bad),
            ]
        )
        == 0
    )
    assert load_part(bad).alpha_y == pytest.approx(math.radians(50))


def test_mesh_outside_the_work_frame(tmp_path, capsys):
    """A mesh above the sheet plane: `part mesh` refuses it (exit 2, one line; issue 29: before,
    it warned and the next toolpath failed)."""
    import trimesh

    stl = tmp_path / "up.stl"
    trimesh.Trimesh([[0, 0, 10], [50, 0, 10], [0, 50, 20]], [[0, 1, 2]], process=False).export(stl)
    toml = tmp_path / "up.toml"
    assert main(["part", "mesh", str(stl), "-o", str(toml)]) == 2
    assert "below the sheet plane" in capsys.readouterr().err
    assert not toml.exists()
