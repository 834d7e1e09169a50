"""Bad geometry, material, mesh and STEP input → a clear InputError naming the field."""

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.fem import (
    BallEndTool,
    HolderSection,
    Material,
    StepGeometry,
    ToolHolder,
    fe_compliance,
    mesh_geometry,
    solve_six_cases,
    step_faces,
)
from roboisf.fem.mesh import _mesh_here, gmsh_session


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"ball_diameter": 0.0, "length": 60e-3}, "ball_diameter"),
        ({"ball_diameter": -10e-3, "length": 60e-3}, "ball_diameter"),
        ({"ball_diameter": 10e-3, "length": 0.0}, "length"),
        ({"ball_diameter": 10e-3, "length": -1.0}, "length"),
        ({"ball_diameter": 10e-3, "length": 4e-3}, "length"),  # shorter than the ball radius
        ({"ball_diameter": 10e-3, "length": 60e-3, "shank_diameter": 0.0}, "shank_diameter"),
        ({"ball_diameter": 10e-3, "length": 60e-3, "shank_diameter": 12e-3}, "shank_diameter"),
        (
            {"ball_diameter": 10e-3, "length": 60e-3, "neck_diameter": 11e-3, "neck_length": 5e-3},
            "neck_diameter",
        ),
        (
            {"ball_diameter": 10e-3, "length": 20e-3, "neck_diameter": 8e-3, "neck_length": 20e-3},
            "neck_length",
        ),
        ({"ball_diameter": 10e-3, "length": float("nan")}, "length"),
    ],
)
def test_impossible_tools(kwargs, field):
    with pytest.raises(InputError) as e:
        BallEndTool(**kwargs)
    assert e.value.field == field


def test_impossible_holders():
    with pytest.raises(InputError) as e:
        HolderSection(0.0, 20e-3)
    assert e.value.field == "length"
    with pytest.raises(InputError) as e:
        HolderSection(10e-3, -20e-3)
    assert e.value.field == "outer_diameter"
    with pytest.raises(InputError, match="bore") as e:
        HolderSection(10e-3, 20e-3, 20e-3)
    with pytest.raises(InputError, match="do not meet") as e:
        ToolHolder((HolderSection(10e-3, 20e-3, 10e-3), HolderSection(10e-3, 40e-3, 25e-3)))
    assert e.value.field == "sections"
    with pytest.raises(InputError, match="at least one"):
        ToolHolder(())
    with pytest.raises(InputError) as e:
        ToolHolder((HolderSection(10e-3, 20e-3),), coupling_diameter=30e-3)
    assert e.value.field == "coupling_diameter"


@pytest.mark.parametrize("nu", [0.5, 0.6, -1.0, float("nan")])
def test_bad_poisson_ratio(nu):
    with pytest.raises(InputError, match="Poisson") as e:
        Material(210e9, nu)
    assert e.value.field == "nu"


def test_bad_youngs_modulus():
    with pytest.raises(InputError) as e:
        Material(0.0, 0.3)
    assert e.value.field == "E"


def test_bad_mesh_sizes():
    tool = BallEndTool(10e-3, 30e-3)
    for h in (0.0, -1e-3, float("inf")):
        with pytest.raises(InputError) as e:
            mesh_geometry(tool, h)
        assert e.value.field == "mesh_size"
    with pytest.raises(InputError, match="larger than the part"):
        mesh_geometry(tool, 1.0)
    with pytest.raises(InputError, match="too fine"):
        mesh_geometry(tool, 1e-6)
    with pytest.raises(InputError, match="solver"):
        solve_six_cases(tool, 5e-3, solver="magic")


def test_a_mesh_that_fails_is_an_input_error(monkeypatch):
    """gmsh failing (here: forced) surfaces as InputError, not a gmsh traceback. Forced in this
    process, so through the work the meshing process runs (tests/test_fem_mesh_isolation.py:
    its InputError arrives here whole)."""
    import gmsh

    def boom(dim=3):
        raise Exception("Invalid boundary mesh (overlapping facets) on surface 1")

    monkeypatch.setattr(gmsh.model.mesh, "generate", boom)
    with pytest.raises(InputError, match="could not mesh") as e:
        _mesh_here(BallEndTool(10e-3, 30e-3), 3e-3)
    assert e.value.field == "geometry"


def _write_rod_step(path, d_mm=10.0, L_mm=50.0):
    with gmsh_session() as (gmsh, _):
        gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, L_mm, d_mm / 2)
        gmsh.model.occ.synchronize()
        gmsh.write(str(path))


def test_step_file_with_named_faces_matches_parametric_rod(tmp_path):
    step = tmp_path / "rod.step"
    _write_rod_step(step)
    faces = step_faces(step)
    planes = {row["face"]: row["bbox_mm"] for row in faces if row["type"] == "Plane"}
    top = next(f for f, bb in planes.items() if bb[2] > 49)
    bottom = next(f for f, bb in planes.items() if bb[5] < 1)
    geom = StepGeometry(step, clamped=(top,), coupling=(str(bottom),))
    k_step = fe_compliance(geom, 4e-3, convergence=False).compliance
    k_rod = fe_compliance(ToolHolder((HolderSection(50e-3, 10e-3),)), 4e-3, convergence=False)
    assert np.allclose(np.diag(k_step), np.diag(k_rod.compliance), rtol=0.02)


def test_step_without_the_named_faces(tmp_path):
    step = tmp_path / "rod.step"
    _write_rod_step(step)
    geom = StepGeometry(step, clamped=("spindle_face",), coupling=("ball",))
    with pytest.raises(InputError, match="no face named 'spindle_face'") as e:
        fe_compliance(geom, 3e-3, convergence=False)
    assert e.value.file == str(step) and e.value.field == "clamped"
    assert "Plane" in str(e.value)  # the message lists the faces the file has
    with pytest.raises(InputError, match="no face number 99"):
        fe_compliance(StepGeometry(step, (99,), (1,)), 3e-3, convergence=False)
    with pytest.raises(InputError, match="not found"):
        fe_compliance(StepGeometry(tmp_path / "nope.step", (1,), (2,)), 3e-3)
    junk = tmp_path / "junk.step"
    junk.write_text("this is not a STEP file\n")
    with pytest.raises(InputError, match="STEP") as e:
        fe_compliance(StepGeometry(junk, (1,), (2,)), 3e-3)
    assert e.value.file == str(junk)
    with pytest.raises(InputError, match="mesh size"):
        fe_compliance(StepGeometry(step, (1,), (2,)))
