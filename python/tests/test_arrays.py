"""Array shapes, dtypes, and that nothing is copied needlessly."""

import numpy as np
import pytest

import hexmss


def test_mesh_arrays_are_cached_read_only_and_typed():
    mesh = hexmss.load_mesh("builtin:critter")
    v, t = mesh.vertices, mesh.triangles
    assert v.shape == (3706, 3) and v.dtype == np.float64
    assert t.shape == (7408, 3) and t.dtype == np.uint32
    assert v.flags.c_contiguous and t.flags.c_contiguous
    # Built once: the same array object on every access, not a new copy.
    assert mesh.vertices is v and mesh.triangles is t
    assert not v.flags.writeable
    with pytest.raises(ValueError):
        v[0, 0] = 1.0
    assert len(mesh) == 7408
    assert t.max() < len(v)


def test_mesh_from_arrays_round_trip():
    # A unit cube, outward winding.
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        dtype=float,
    )
    t = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
         [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 4, 7], [0, 7, 3]]
    mesh = hexmss.Mesh(v, t)
    assert mesh.volume == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(mesh.vertices, v)
    np.testing.assert_array_equal(mesh.triangles, np.array(t, dtype=np.uint32))
    lattice = hexmss.voxelize(mesh, cells=4)
    assert lattice.num_cells == 64 and lattice.num_nodes == 125
    assert lattice.volume == pytest.approx(1.0)


def test_lattice_arrays():
    lattice = hexmss.Lattice.block((4, 3, 2), 0.01, origin=(1.0, 2.0, 3.0))
    assert lattice.dims == [4, 3, 2]
    nodes, cells = lattice.nodes, lattice.cells
    assert nodes.shape == (5 * 4 * 3, 3) and nodes.dtype == np.float64
    assert cells.shape == (24, 8) and cells.dtype == np.uint32
    assert lattice.nodes is nodes and not nodes.flags.writeable
    assert lattice.cell_coords.shape == (24, 3)
    assert lattice.node_coords.dtype == np.uint32
    np.testing.assert_allclose(nodes.min(axis=0), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(nodes.max(axis=0), [1.04, 2.03, 3.02])
    # Every cell's corners span one cell edge along each axis.
    corners = nodes[cells]
    np.testing.assert_allclose(np.ptp(corners, axis=1), 0.01, rtol=1e-12)
    skin = lattice.skin()
    # A 4x3x2 box has 2 (12 + 8 + 6) boundary quads, two triangles each.
    assert skin.triangles.shape == (4 * 26, 3)
    np.testing.assert_array_equal(skin.positions(nodes), nodes[skin.vertex_nodes])


def test_model_and_state_arrays():
    lattice = hexmss.Lattice.block((3, 3, 3), 0.02)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    assert model.masses.shape == (64,) and model.masses.dtype == np.float64
    assert model.total_mass == pytest.approx(1000.0 * 0.06**3)
    assert model.masses.sum() == pytest.approx(model.total_mass)
    x = model.rest_positions
    np.testing.assert_array_equal(x, lattice.nodes)
    f = model.internal_forces(x)
    assert f.shape == (64, 3)
    assert np.abs(f).max() < 1e-9  # at rest
    out = np.empty((64, 3))
    assert model.internal_forces(x, out=out) is out
    with pytest.raises(TypeError, match="float64"):
        model.internal_forces(x, out=np.empty((64, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        model.internal_forces(x, out=np.empty((63, 3)))
    with pytest.raises(ValueError, match="contiguous"):
        model.internal_forces(x, out=np.empty((64, 6))[:, ::2])
    with pytest.raises(ValueError):
        model.internal_forces(x[:10])
    problem = hexmss.Problem(model, fixed=[{"kind": "face", "face": "z-"}])
    state = hexmss.State(problem)
    assert state.x.shape == (64, 3) and state.v.shape == (64, 3)
    buf = np.zeros((64, 3))
    assert state.positions_into(buf) is buf
    np.testing.assert_array_equal(buf, x)
    moved = x + 0.001
    state.x = moved
    np.testing.assert_array_equal(state.x, moved)
    np.testing.assert_allclose(state.displacements(model), 0.001)


def test_inputs_of_other_dtypes_and_lists_are_accepted():
    lattice = hexmss.Lattice.block((2, 2, 2), 0.05)
    model = hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))
    x32 = lattice.nodes.astype(np.float32)
    f = model.internal_forces(x32)
    assert f.dtype == np.float64
    f2 = model.internal_forces(lattice.nodes.tolist())
    np.testing.assert_allclose(f, f2, atol=1e-3)
