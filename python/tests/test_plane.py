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
