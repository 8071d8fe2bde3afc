"""2D scenes (the paper's rectangles, plane stress) through the same API:
hexmss.run takes a scene with [model] dimension = 2."""

import hexmss
from conftest import DATA


def test_a_2d_scene_runs_and_reports_its_plane_body(tmp_path):
    text = (DATA / "scenes" / "bracket.toml").read_text()
    text = text.replace("../shapes/bracket.svg", str(DATA / "shapes" / "bracket.svg"))
    text = text.replace('kind = "explicit"', 'kind = "static"')
    scene = tmp_path / "bracket.toml"
    scene.write_text(text)
    summary = hexmss.run(scene, tmp_path / "out")
    assert summary["dimension"] == 2
    assert summary["cells"] == 344
    assert summary["max_displacement"] > 5e-3
    assert (tmp_path / "out" / "outline_0001.svg").exists()


def test_the_2d_model_level_api_stretches_a_strip_as_hooke_says():
    # A strip (nu = 0: uniaxial) held at x = 0, 0.1 N pulling its free face
    # (shared by its 3 nodes): u = F L / (E t H) within 2 % (the uneven
    # share at the face); the explicit damped run and implicit steps agree.
    import numpy as np

    lattice = hexmss.RectLattice.block((8, 2), (0.02, 0.01))
    assert lattice.num_cells == 16 and lattice.nodes.shape == (27, 2)
    assert lattice.cells.shape == (16, 4)
    model = hexmss.PlaneModel(lattice, hexmss.Material(1e5, 0.0, 1000.0), thickness=0.01)
    assert model.dimension == 2 and hexmss.Model.dimension.__doc__
    assert model.parameterization == "paper+hg"
    assert abs(model.total_mass - 1000.0 * 0.16 * 0.02 * 0.01) < 1e-12
    rest = model.rest_positions
    assert rest.shape == (27, 3) and np.all(rest[:, 2] == 0.0)
    assert np.abs(model.internal_forces(rest)).max() < 1e-12
    problem = hexmss.PlaneProblem(
        model,
        fixed=[{"kind": "face", "face": "x-"}],
        forces=[{"select": {"kind": "face", "face": "x+"}, "force": [0.1, 0.0, 0.0]}],
        damping=80.0,
    )
    assert len(problem.held_nodes) == 3
    x = problem.solve_static()
    face = np.abs(rest[:, 0] - 0.16) < 1e-12
    u = (x[face, 0] - rest[face, 0]).mean()
    hooke = 0.1 * 0.16 / (1e5 * 0.01 * 0.02)
    assert abs(u / hooke - 1.0) < 0.02, (u, hooke)
    dt = problem.stable_time_step()
    xe, ve = problem.step(rest, np.zeros_like(rest), dt, n=int(0.5 / dt))
    assert abs(xe[:, 0].max() - x[:, 0].max()) < 1e-3 * hooke
    xi, vi = problem.step(rest, np.zeros_like(rest), 0.01, n=50, implicit=True)
    assert abs(xi[:, 0].max() - x[:, 0].max()) < 1e-3 * hooke


def test_2d_model_level_errors_are_typed():
    import numpy as np
    import pytest

    lattice = hexmss.RectLattice.rasterize([[[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]]], (0.01, 0.01))
    assert lattice.num_cells == 50
    mat = hexmss.Material(1e5, 0.3, 1000.0)
    with pytest.raises(hexmss.ModelError, match="parameterization"):
        hexmss.PlaneModel(lattice, mat, 0.01, parameterization="volumetric")
    with pytest.raises(hexmss.ModelError, match="thickness"):
        hexmss.PlaneModel(lattice, mat, -1.0)
    model = hexmss.PlaneModel(lattice, mat, 0.01)
    with pytest.raises(hexmss.ModelError, match="x-y plane"):
        hexmss.PlaneProblem(model, gravity=[0, 0, -9.81])
    with pytest.raises(hexmss.ModelError, match="no z faces"):
        hexmss.PlaneProblem(model, fixed=[{"kind": "face", "face": "z-"}])
    problem = hexmss.PlaneProblem(model, fixed=[{"kind": "lowest_layer"}], gravity=[0, -9.81, 0])
    rest = model.rest_positions
    with pytest.raises(hexmss.SolverError, match="stable"):
        problem.step(rest, np.zeros_like(rest), 1.0)
    lifted = rest.copy()
    lifted[0, 2] = 1.0
    with pytest.raises(hexmss.ModelError, match="z = 0"):
        model.energy(lifted)
