"""Scenes of several bodies: each body's nodes, stepping them together, the
force between them in the summary."""

import numpy as np

import hexmss
from conftest import DATA


def test_a_stack_names_its_bodies_and_their_nodes(tmp_path):
    job = hexmss.prepare(DATA / "scenes" / "stack.toml")
    assert job.body_names == ["lower", "upper"]
    (a0, a1), (b0, b1) = job.body_nodes
    assert a0 == 0 and a1 == b0 and b1 == job.model.num_nodes
    sim = job.simulation()
    for _ in range(100):
        sim.step(0.005)
    x = sim.positions
    # The upper cube has fallen 5 mm onto the lower one and lies on it:
    # its base within half a millimetre of the lower cube's top.
    assert abs(x[b0:b1, 2].min() - x[a0:a1, 2].max()) < 5e-4


def test_a_settled_stack_simulation_starts_at_rest_and_stays(tmp_path):
    # No damping at all: started at rest in its rest shape, the upper cube
    # would fall 5 mm and ring; settled, it lies on the lower one from the
    # first frame and stays.
    text = (DATA / "scenes" / "stack.toml").read_text()
    text = text.replace("damping = 10.0", 'damping = 0.0\nstart = "settled"')
    scene = tmp_path / "stack.toml"
    scene.write_text(text)
    job = hexmss.prepare(scene)
    (a0, a1), (b0, b1) = job.body_nodes
    sim = job.simulation()
    x0 = sim.positions
    assert abs(x0[b0:b1, 2].min() - x0[a0:a1, 2].max()) < 5e-4
    for _ in range(20):
        sim.step(1.0 / 60.0)
    assert np.abs(sim.positions - x0).max() < 1e-5
    info = sim.settle()
    assert info["relative_residual"] <= 1e-4 and info["steps"] >= 0


def test_the_summary_lists_each_body_with_the_force_of_the_others(tmp_path):
    text = (DATA / "scenes" / "squeeze.toml").read_text()
    text = text.replace("duration = 1.2", "duration = 0.5").replace("cells = 12", "cells = 6")
    scene = tmp_path / "squeeze.toml"
    scene.write_text(text)
    summary = hexmss.run(scene, tmp_path / "out")
    names = [b["name"] for b in summary["bodies"]]
    assert names == ["block", "ball"]
    forces = np.array([b["contact_force_from_bodies"] for b in summary["bodies"]])
    assert forces[1, 2] > 0.0
    assert np.allclose(forces[0], -forces[1], atol=1e-9 * abs(forces[1, 2]))
