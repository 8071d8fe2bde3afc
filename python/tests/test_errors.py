"""Errors arrive as typed exceptions with the CLI's one-line messages."""

import subprocess

import numpy as np
import pytest

import hexmss
from conftest import small_scene


def test_exception_hierarchy():
    assert issubclass(hexmss.SceneError, hexmss.HexmssError)
    assert issubclass(hexmss.SceneError, ValueError)
    assert issubclass(hexmss.DivergedError, hexmss.SolverError)
    assert issubclass(hexmss.MechanismError, hexmss.SolverError)
    assert issubclass(hexmss.OutputError, OSError)


def test_same_message_as_the_cli(tmp_path, mss_binary):
    scene = tmp_path / "bad.toml"
    scene.write_text(
        '[mesh]\npath = "builtin:critter"\n[material]\nyoung = 1e5\npoisson = 0.3\ndensty = 1000\n'
    )
    cli = subprocess.run(
        [str(mss_binary), "run", str(scene)], capture_output=True, text=True
    )
    assert cli.returncode == 1
    with pytest.raises(hexmss.SceneError) as e:
        hexmss.run(scene, out=tmp_path / "out")
    assert cli.stderr.strip() == f"error: {e.value}"
    assert "densty" in str(e.value) and ":6:" in str(e.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "call, kind, words",
    [
        (lambda: hexmss.Material(1e5, 0.5, 1000), hexmss.ModelError, "Poisson"),
        (lambda: hexmss.Material(-1, 0.3, 1000), hexmss.ModelError, "Young"),
        (lambda: hexmss.load_mesh("/no/such/mesh.obj"), hexmss.MeshError, "does not exist"),
        (lambda: hexmss.load_mesh("builtin:nothing"), hexmss.MeshError, "builtin:critter"),
        (lambda: hexmss.load_mesh("builtin:critter", up="w"), hexmss.SceneError, "up"),
        (
            lambda: hexmss.voxelize(hexmss.load_mesh("builtin:critter"), cells=0),
            hexmss.VoxelizeError,
            "0",
        ),
        (
            lambda: hexmss.voxelize(hexmss.load_mesh("builtin:critter"), cels=4),
            hexmss.SceneError,
            "cels",
        ),
        (
            lambda: hexmss.Model(
                hexmss.Lattice.block((2, 2, 2), 0.1), hexmss.Material(1e5, 0.3, 1e3), "nope"
            ),
            hexmss.ModelError,
            "nope",
        ),
        (lambda: hexmss.Scene.from_toml("[mesh]\npath = 3\n"), hexmss.SceneError, "path"),
        (lambda: hexmss.run(small_scene(solver={"dt": -1.0})), hexmss.SceneError, "dt"),
        (
            lambda: hexmss.prepare(small_scene(), max_memory="1KiB"),
            hexmss.ResourceError,
            "memory",
        ),
    ],
)
def test_bad_values_raise_typed_errors(call, kind, words):
    with pytest.raises(kind) as e:
        call()
    assert words.lower() in str(e.value).lower()
    assert "\n" not in str(e.value)
    # A sentence, not Rust's Debug text or paths.
    for raw in ["Some(", "None)", "Error {", "Error(", "::", "Resolution", " { "]:
        assert raw not in str(e.value), str(e.value)


def test_free_static_problem_is_a_mechanism():
    lattice = hexmss.Lattice.block((2, 2, 2), 0.05)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    problem = hexmss.Problem(model, gravity=[0, 0, -9.81])
    with pytest.raises(hexmss.MechanismError) as e:
        hexmss.solve_static(problem)
    assert "fix" in str(e.value)


def test_array_arguments_are_checked():
    lattice = hexmss.Lattice.block((2, 2, 2), 0.05)
    with pytest.raises(ValueError):
        hexmss.Mesh(np.zeros((4, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError):
        hexmss.Mesh(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(ValueError):
        hexmss.Mesh([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(TypeError):
        hexmss.Mesh("vertices", [[0, 1, 2]])
    with pytest.raises(ValueError):
        hexmss.write_vtu("x.vtu", lattice, np.zeros((3, 3)))
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    sim = hexmss.Simulation(hexmss.Problem(model))
    with pytest.raises(ValueError):
        sim.pick([10_000], 10.0)
    with pytest.raises(hexmss.SceneError):
        sim.pick([0], -1.0)
    with pytest.raises(hexmss.SceneError):
        sim.step(0.0)
    with pytest.raises(ValueError):
        hexmss.set_threads(0)


def test_unwritable_output_is_an_output_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(hexmss.OutputError):
        hexmss.run(small_scene(), out=blocker / "out")


def test_messages_speak_python():
    # An unstable equilibrium: springs alone, a cantilever under its weight
    # and a tip load (mss-core's equilibrium test).
    lattice = hexmss.Lattice.block((20, 4, 4), 0.01)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0), "springs")
    problem = hexmss.Problem(
        model,
        fixed=[{"kind": "face", "face": "x-"}],
        gravity=[0, 0, -9.81],
        forces=[{"select": {"kind": "face", "face": "x+"}, "force": [0, 0, -0.05]}],
    )
    with pytest.raises(hexmss.MechanismError) as e:
        hexmss.solve_static(problem)
    text = str(e.value)
    assert "accept_unstable=True" in text and "[solver]" not in text and "::" not in text
    state, _ = hexmss.solve_static(problem, accept_unstable=True)
    # A missing mesh is relative to the working directory, not to a scene.
    with pytest.raises(hexmss.MeshError, match="working directory"):
        hexmss.load_mesh("surely-missing-mesh.obj")
    # A float32 output array is named by its dtype and shape.
    out = np.zeros((model.num_nodes, 3), dtype=np.float32)
    with pytest.raises(TypeError, match="dtype float32 and shape"):
        model.internal_forces(lattice.nodes, out=out)
    sim = hexmss.Simulation(problem)
    assert repr(sim).startswith(f"Simulation({model.num_nodes} nodes, t = 0")


def _diverging_run():
    # Every node flung apart at 100 m/s: cells invert within a sub-step,
    # whatever the step control halves.
    lattice = hexmss.Lattice.block((3, 3, 3), 0.05)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    problem = hexmss.Problem(model)
    state = hexmss.State(problem)
    rng = np.random.default_rng(3)
    state.v = rng.normal(scale=100.0, size=state.x.shape)
    hexmss.Integrator(problem, "explicit").step(state, n=50)


def _too_long_a_step():
    lattice = hexmss.Lattice.block((3, 3, 3), 0.05)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    hexmss.Integrator(hexmss.Problem(model), "explicit", dt=1.0)


def _mechanism():
    lattice = hexmss.Lattice.block((4, 1, 1), 0.05)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0), "springs")
    problem = hexmss.Problem(
        model, fixed=[{"kind": "face", "face": "x-"}], gravity=[0, 0, -9.81]
    )
    hexmss.solve_static(problem)


def _subclasses(cls):
    for sub in cls.__subclasses__():
        yield sub
        yield from _subclasses(sub)


def test_every_error_class_is_raised_as_itself_with_one_plain_sentence(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    cases = {
        hexmss.SceneError: lambda: hexmss.Scene.from_toml("[mesh]\npath = 3\n"),
        hexmss.MeshError: lambda: hexmss.load_mesh(str(tmp_path / "missing.obj")),
        hexmss.VoxelizeError: lambda: hexmss.voxelize(hexmss.load_mesh("builtin:critter"), cells=0),
        hexmss.ModelError: lambda: hexmss.Material(1e5, 0.5, 1000.0),
        hexmss.SolverError: _too_long_a_step,
        hexmss.DivergedError: _diverging_run,
        hexmss.MechanismError: _mechanism,
        hexmss.OutputError: lambda: hexmss.run(small_scene(), out=blocker / "out"),
        hexmss.ResourceError: lambda: hexmss.prepare(small_scene(), max_memory="1KiB"),
    }
    # A class added without a case here fails this test.
    assert set(cases) == set(_subclasses(hexmss.HexmssError))
    for kind, call in cases.items():
        with pytest.raises(hexmss.HexmssError) as e:
            call()
        assert type(e.value) is kind, (kind, type(e.value), str(e.value))
        text = str(e.value)
        assert text and "\n" not in text, text
        for raw in ["Some(", "None)", "Error {", "Error(", "::", " { ", "{:?}"]:
            assert raw not in text, (kind, text)
