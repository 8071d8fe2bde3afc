"""Writing frames and skins, read back."""

import numpy as np
import pytest

import hexmss


def test_vtu_and_obj_round_trip(tmp_path):
    lattice = hexmss.Lattice.block((3, 2, 2), 0.1)
    x = lattice.nodes * 1.5
    hexmss.write_vtu(
        tmp_path / "f.vtu",
        lattice,
        x,
        point_data={"u": x - lattice.nodes, "id": np.arange(lattice.num_nodes)},
        cell_data={"c": np.ones(lattice.num_cells)},
        encoding="ascii",
    )
    text = (tmp_path / "f.vtu").read_text()
    assert 'NumberOfPoints="36"' in text and 'NumberOfCells="12"' in text
    assert 'Name="u"' in text and 'Name="c"' in text
    skin = lattice.skin()
    hexmss.write_obj(tmp_path / "s.obj", skin.positions(x), skin.triangles, normals="flat")
    mesh = hexmss.load_mesh(tmp_path / "s.obj")
    assert mesh.volume == pytest.approx(lattice.volume * 1.5**3, rel=1e-12)
    hexmss.write_stl(tmp_path / "s.stl", skin.positions(x), skin.triangles)
    again = hexmss.load_mesh(tmp_path / "s.stl")
    assert again.volume == pytest.approx(mesh.volume, rel=1e-6)
    assert not list(tmp_path.glob("*.tmp*"))


def test_placement_keys(tmp_path):
    mesh = hexmss.load_mesh("builtin:critter")
    placed = hexmss.load_mesh("builtin:critter", units="cm", translate=[1.0, 0.0, 0.0])
    np.testing.assert_allclose(placed.vertices, mesh.vertices * 0.01 + [1.0, 0.0, 0.0])
    again = mesh.place(scale=2.0)
    assert again.volume == pytest.approx(8 * mesh.volume)
