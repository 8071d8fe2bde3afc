"""The library from Python: facts of the model, solvers that agree."""

import numpy as np
import pytest

import hexmss


def bar(cells=(8, 2, 2), h=0.025, param="volumetric-barrier+hg", young=1e5):
    lattice = hexmss.Lattice.block(cells, h)
    model = hexmss.Model(lattice, hexmss.Material(young, 0.3, 1000.0), param)
    return lattice, model


def test_parameterizations_and_integrators_are_listed():
    assert {"paper", "springs", "volumetric", "volumetric-barrier"} <= set(
        hexmss.parameterizations()
    )
    assert {"explicit", "implicit"} <= set(hexmss.integrators())


def test_rigid_motion_has_no_force_and_no_energy():
    lattice, model = bar(param="paper")
    x = lattice.nodes
    c = np.cos(0.3)
    s = np.sin(0.3)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    moved = x @ rot.T + [0.1, -0.2, 0.3]
    assert np.abs(model.internal_forces(moved)).max() < 1e-8
    assert abs(model.energy(moved)) < 1e-12


def test_forces_are_minus_the_energy_gradient():
    # Springs alone are conservative (the correction forces of the other
    # parameterizations have no energy).
    lattice, model = bar(param="springs")
    rng = np.random.default_rng(1)
    x = lattice.nodes + rng.normal(scale=1e-3, size=lattice.nodes.shape)
    f = model.internal_forces(x)
    eps = 1e-7
    for node, axis in [(3, 0), (17, 2), (40, 1)]:
        xp = x.copy()
        xp[node, axis] += eps
        xm = x.copy()
        xm[node, axis] -= eps
        grad = (model.energy(xp) - model.energy(xm)) / (2 * eps)
        assert f[node, axis] == pytest.approx(-grad, rel=1e-5, abs=1e-6)


def test_static_and_damped_explicit_agree():
    lattice, model = bar()
    problem = hexmss.Problem(
        model,
        fixed=[{"kind": "face", "face": "x-"}],
        gravity=[0.0, 0.0, -9.81],
        damping=60.0,
    )
    static, info = hexmss.solve_static(problem)
    assert info["stable"] is True
    assert info["relative_residual"] < 1e-6
    u_static = static.displacements(model)
    tip = np.abs(u_static).max()
    assert tip > 1e-4
    state = hexmss.State(problem)
    integ = hexmss.Integrator(problem, "explicit")
    integ.step(state, n=int(1.5 / integ.dt))
    u_dyn = state.displacements(model)
    assert np.abs(u_dyn - u_static).max() < 0.01 * tip
    # The weight is carried: reactions at the held face balance gravity.
    free = model.internal_forces(static.x) + problem.external_forces(static.x)
    held = problem.held_nodes
    reaction = -free[held].sum(axis=0)
    assert reaction[2] == pytest.approx(model.total_mass * 9.81, rel=1e-6)


def test_implicit_step_and_linear_static():
    lattice, model = bar(young=1e7)
    problem = hexmss.Problem(
        model, fixed=[{"kind": "face", "face": "x-"}], gravity=[0, 0, -9.81]
    )
    nonlinear, _ = hexmss.solve_static(problem)
    linear, _ = hexmss.solve_static(problem, linear=True)
    u_n = nonlinear.displacements(model)
    u_l = linear.displacements(model)
    # Small strain: both answers within a percent.
    assert np.abs(u_n - u_l).max() < 0.01 * np.abs(u_n).max()
    state = hexmss.State(problem)
    implicit = hexmss.Integrator(problem, "implicit", dt=0.01)
    info = implicit.step(state, n=3)
    assert info["steps"] == 3 and info["newton_iterations"] >= 3
    assert state.time == pytest.approx(0.03)


def test_free_body_conserves_momentum():
    lattice, model = bar(param="paper")
    problem = hexmss.Problem(model)
    state = hexmss.State(problem)
    rng = np.random.default_rng(7)
    v = rng.normal(scale=0.05, size=(model.num_nodes, 3))
    state.v = v
    m = model.masses[:, None]
    p0 = (m * v).sum(axis=0)
    hexmss.Integrator(problem, "explicit").step(state, n=200)
    p1 = (m * state.v).sum(axis=0)
    np.testing.assert_allclose(p1, p0, atol=1e-12)


def test_simulation_drag_and_surface():
    lattice, model = bar(cells=(4, 4, 2))
    problem = hexmss.Problem(
        model,
        obstacles=[{"shape": {"kind": "ground", "gap": 0.0}, "friction": 0.5}],
        gravity=[0, 0, -9.81],
        damping=5.0,
    )
    sim = hexmss.Simulation(problem)
    corner = sim.nearest_node([0.1, 0.1, 0.05])
    sim.pick([corner], 50.0)
    sim.drag_to([0.1, 0.1, 0.08])
    for _ in range(20):
        assert sim.step(1 / 60) >= 1
    assert sim.positions[corner, 2] > 0.05
    assert sim.time == pytest.approx(20 / 60)
    out = np.empty((model.num_nodes, 3))
    assert sim.positions_into(out) is out
    np.testing.assert_array_equal(out, sim.positions)
    sim.release()
    with pytest.raises(hexmss.SceneError):
        sim.surface_positions()
    # Resting on the ground: nothing sinks far below it.
    for _ in range(60):
        sim.step(1 / 60)
    assert sim.positions[:, 2].min() > -0.002


def test_single_precision_force_pass_is_close_to_double():
    def run(precision, through_simulation):
        lattice, model = bar(cells=(4, 4, 2))
        problem = hexmss.Problem(
            model, gravity=[0, 0, -9.81], damping=5.0, fixed=[{"kind": "lowest_layer"}]
        )
        if through_simulation:
            sim = hexmss.Simulation(problem)
            sim.precision = precision
            assert sim.precision == precision
            for _ in range(10):
                sim.step(1 / 60)
            return sim.positions
        state = hexmss.State(problem)
        hexmss.Integrator(problem, "explicit", precision=precision).step(state, n=300)
        return state.x

    for through_simulation in (True, False):
        double = run("f64", through_simulation)
        single = run("f32", through_simulation)
        moved = np.abs(double - run("f64", through_simulation)).max()
        assert moved == 0.0
        diff = np.abs(single - double).max()
        assert 0.0 < diff < 1e-6
    with pytest.raises(hexmss.SceneError, match="f32"):
        sim = hexmss.Simulation(hexmss.Problem(bar()[1]))
        sim.precision = "f16"


def test_job_simulation_deforms_the_scene_mesh():
    scene = hexmss.Scene.default()
    job = hexmss.prepare(scene)
    sim = job.simulation()
    rest = sim.surface_positions()
    assert rest.shape == job.mesh.vertices.shape
    np.testing.assert_allclose(rest, job.mesh.vertices, atol=1e-12)
    sim.step(0.05)
    sagged = sim.surface_positions()
    assert sagged[:, 2].mean() < rest[:, 2].mean()


def test_embedding_follows_a_translation():
    mesh = hexmss.load_mesh("builtin:critter")
    lattice = hexmss.voxelize(mesh, cells=8, rule="any")
    emb = lattice.embed(mesh)
    moved = emb.deform(lattice.nodes + [0.5, 0.0, -0.25])
    np.testing.assert_allclose(moved, mesh.vertices + [0.5, 0.0, -0.25], atol=1e-12)


def test_custom_loads_by_kind_are_the_builtin_tables():
    lattice, model = bar()
    fixed = [{"kind": "face", "face": "x-"}]
    by_key = hexmss.Problem(model, fixed=fixed, gravity=[0, 0, -9.81])
    by_kind = hexmss.Problem(
        model, fixed=fixed, custom_loads=[{"kind": "gravity", "g": [0, 0, -9.81]}]
    )
    x = lattice.nodes
    assert np.array_equal(by_key.external_forces(x), by_kind.external_forces(x))
    assert np.abs(by_kind.external_forces(x)).max() > 0
    with pytest.raises(hexmss.SceneError, match=r"custom_loads\[0\].*known: gravity"):
        hexmss.Problem(model, custom_loads=[{"kind": "wind"}])


def test_static_solve_follows_a_pressing_obstacle_from_rest():
    # A box moving 1.5 cm (1.2 cells) down into a held block by t = 0.2 s:
    # followed from rest, the static solve gives the press's force; solved
    # where it ends, the box is inserted from above (its shortest way out),
    # the same press. (Placed at once, it pushed the nodes near its edges
    # out sideways: a seventh of the force.)
    lattice = hexmss.Lattice.block((8, 8, 4), 0.0125)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0), "volumetric-barrier+hg")
    box = {
        "shape": {"kind": "box", "min": [0.03, 0.03, 0.05], "max": [0.07, 0.07, 0.09]},
        "motion": [[0.0, 0.0, 0.0, 0.0], [0.2, 0.0, 0.0, -0.015]],
        "friction": 0.5,
    }
    problem = hexmss.Problem(model, fixed=[{"kind": "lowest_layer"}], obstacles=[box])
    start = hexmss.State(problem)
    start.time = 0.4
    followed, info = hexmss.solve_static(problem, start, obstacles_from=0.0, accept_unstable=True)
    at_once, _ = hexmss.solve_static(problem, start, accept_unstable=True)
    push = lambda s: problem.contact_forces(s)[:, 2].sum()
    assert info["load_steps"] >= 5
    assert push(followed) < -50.0
    assert abs(push(at_once) - push(followed)) < 0.02 * abs(push(followed))
    with pytest.raises(ValueError, match="obstacles_from"):
        hexmss.solve_static(problem, start, obstacles_from=float("nan"))


def test_a_corner_pushed_through_is_folded_not_inverted():
    # One cell; its corner 0 pushed along the diagonal by 0.4 h: that corner's
    # Jacobian is 1 - 3 * 0.4 < 0 while the centre's stays positive.
    model = hexmss.Model(
        hexmss.Lattice.block((1, 1, 1), 0.01),
        hexmss.Material(1e5, 0.3, 1000.0),
        "volumetric-barrier+hg",
    )
    x = np.array(model.rest_positions)
    corner = int(np.argmin(x.sum(axis=1)))
    assert model.folded_cells(x) == [] and model.corner_jacobians(x)[0] == pytest.approx(1.0)
    x[corner] += 0.004
    assert model.corner_jacobians(x)[0] == pytest.approx(1.0 - 3 * 0.4)
    assert model.folded_cells(x) == [0]
    assert model.inverted_cells(x) == []
