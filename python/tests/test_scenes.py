"""Scenes and runs: the same numbers as the CLI, for any thread count."""

import json
import subprocess

import numpy as np
import pytest

import hexmss
from conftest import DATA, small_scene

# Fields of summary.json that measure the machine, not the simulation; and
# the verdict of the load check before a run, which a resumed run does not
# repeat and which a slow machine may stop at its time limit.
TIMING_FIELDS = {
    "voxelize_seconds",
    "simulate_seconds",
    "wall_seconds",
    "peak_memory_bytes",
    "output_folder",
    "scene",
    "load_check",
}


def frames(folder):
    return sorted(p for p in folder.iterdir() if p.suffix in {".vtu", ".obj"})


def physics(summary):
    return {k: v for k, v in summary.items() if k not in TIMING_FIELDS}


@pytest.mark.parametrize("solver", ["explicit", "implicit", "static"])
def test_run_is_bitwise_the_cli(tmp_path, mss_binary, solver):
    scene = small_scene(solver={"kind": solver})
    if solver == "implicit":
        scene["solver"]["dt"] = 0.02
    path = tmp_path / "scene.toml"
    # The same scene as a file, for both front ends.
    import tomllib  # noqa: F401  (3.11+, only to be sure the text parses)

    path.write_text(toml_text(scene))
    cli_out = tmp_path / "cli"
    subprocess.run(
        [str(mss_binary), "--quiet", "run", str(path), "--out", str(cli_out)],
        check=True,
    )
    py_out = tmp_path / "py"
    summary = hexmss.run(path, out=py_out)
    cli_summary = json.loads((cli_out / "summary.json").read_text())
    assert physics(summary) == physics(cli_summary)
    a, b = frames(cli_out), frames(py_out)
    assert [p.name for p in a] == [p.name for p in b] and a
    for x, y in zip(a, b):
        assert x.read_bytes() == y.read_bytes(), x.name


def toml_text(d):
    """A small TOML writer for the test scenes (tables of scalars and lists)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    lines = []
    for table, body in d.items():
        if isinstance(body, list):
            for item in body:
                lines.append(f"[[{table}]]")
                lines += [f"{k} = {value(v)}" for k, v in item.items()]
        else:
            lines.append(f"[{table}]")
            lines += [f"{k} = {value(v)}" for k, v in body.items()]
    return "\n".join(lines) + "\n"


def test_scene_from_dict_toml_and_file_agree(tmp_path):
    d = small_scene()
    from_dict = hexmss.run(hexmss.Scene.from_dict(d), out=tmp_path / "a")
    from_toml = hexmss.run(hexmss.Scene.from_toml(toml_text(d)), out=tmp_path / "b")
    assert physics(from_dict) == physics(from_toml)
    assert from_dict["frames"] == 3
    assert from_dict["cells"] == hexmss.prepare(d).lattice.num_cells


def test_results_do_not_depend_on_the_thread_count(tmp_path):
    results = []
    for threads in (1, 2):
        hexmss.set_threads(threads)
        assert hexmss.get_threads() == threads
        out = tmp_path / f"t{threads}"
        summary = hexmss.run(small_scene(), out=out)
        lattice, model = bar_model()
        problem = hexmss.Problem(
            model, fixed=[{"kind": "face", "face": "x-"}], gravity=[0, 0, -9.81]
        )
        static, _ = hexmss.solve_static(problem)
        state = hexmss.State(problem)
        hexmss.Integrator(problem, "explicit").step(state, n=50)
        results.append((summary, [p.read_bytes() for p in frames(out)], static.x, state.x))
    (s1, f1, a1, b1), (s2, f2, a2, b2) = results
    assert physics(s1) == physics(s2)
    assert f1 == f2
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(b1, b2)


def bar_model():
    lattice = hexmss.Lattice.block((16, 4, 4), 0.0125)
    return lattice, hexmss.Model(lattice, hexmss.Material(1e5, 0.3, 1000.0))


def test_progress_callback_sees_every_stage(tmp_path):
    seen = []
    hexmss.run(small_scene(), out=tmp_path, progress=lambda *a: seen.append(a))
    stages = {s for s, _, _ in seen}
    assert {"voxelizing", "stepping"} <= stages
    done, total = max((d, t) for s, d, t in seen if s == "stepping")
    assert done == total > 0


def test_an_exception_in_the_callback_stops_the_run_cleanly(tmp_path):
    class Stop(Exception):
        pass

    def progress(stage, done, total):
        if stage == "stepping" and done > 0:
            raise Stop

    scene = small_scene(solver={"duration": 2.0})
    with pytest.raises(Stop):
        hexmss.run(scene, out=tmp_path, progress=progress)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert summary["simulated_time"] < 2.0
    assert frames(tmp_path)


def test_job_exposes_what_it_built(tmp_path):
    job = hexmss.prepare(small_scene())
    assert job.lattice.num_cells == job.model.num_cells
    assert job.problem.num_nodes == job.lattice.num_nodes
    assert job.dt <= job.stable_time_step * (1 + 1e-12)
    assert job.steps * job.dt == pytest.approx(0.1)
    assert not job.is_static
    summary = job.run(tmp_path)
    assert summary["steps"] == job.steps
    assert (tmp_path / "summary.json").exists()


def test_bundled_scenes_load():
    for name in ["default.toml", "drop.toml", "press.toml", "template.toml"]:
        scene = hexmss.Scene.from_file(DATA / "scenes" / name)
        assert scene.duration > 0
    assert hexmss.Scene.default().name == "<bundled default.toml>"


def test_the_gil_is_released_during_a_run(tmp_path):
    import threading

    # The main thread acts while the run is under way, and the run stops
    # because of it: impossible if the run held the GIL from start to end
    # (the main thread could then only act once the run was over). No
    # clock is read: the run is far longer than the steps below take.
    class Stop(Exception):
        pass

    stepping = threading.Event()
    stop = threading.Event()

    def progress(stage, done, total):
        if stage == "stepping":
            stepping.set()
        if stop.is_set():
            raise Stop()

    scene = small_scene(voxelize={"cells": 16}, solver={"duration": 30.0})
    outcome = {}

    def work():
        try:
            hexmss.run(scene, tmp_path, progress=progress)
            outcome["finished"] = True
        except Stop:
            outcome["stopped"] = True

    worker = threading.Thread(target=work)
    worker.start()
    stepping.wait()
    # Python code running here, in the main thread, while the run steps.
    stop.set()
    worker.join()
    assert outcome == {"stopped": True}
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert summary["simulated_time"] < 30.0


def test_ctrl_c_stops_a_run_with_its_frames_written(tmp_path):
    import _thread
    import threading

    # A run far longer than the wait, so that Ctrl-C lands inside it.
    scene = small_scene(voxelize={"cells": 16}, solver={"duration": 1000.0}, output={"every_time": 1.0})
    threading.Timer(0.3, _thread.interrupt_main).start()
    with pytest.raises(KeyboardInterrupt):
        hexmss.run(scene, out=tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert 0 < summary["simulated_time"] < 1000.0
    assert frames(tmp_path)


def test_the_sag_example_runs(tmp_path):
    import sys

    example = DATA.parent / "python" / "examples" / "sag.py"
    done = subprocess.run(
        [sys.executable, str(example), "--cells", "12", "--duration", "0.1",
         "--plot", str(tmp_path / "sag.png")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "static equilibrium: top sinks" in done.stdout
    assert "inverted cells: 0" in done.stdout


def test_an_interrupted_run_resumes_to_the_uninterrupted_files(tmp_path):
    # Long enough (about a second) that progress is reported between a third
    # of the run and its end (reports come at most every 50 ms).
    scene = small_scene(
        voxelize={"cells": 16}, solver={"duration": 3.0}, output={"every_time": 0.25, "pc2": True}
    )
    whole = tmp_path / "whole"
    reference = hexmss.run(scene, out=whole)

    class Stop(Exception):
        pass

    def stop(stage, done, total):
        if stage == "stepping" and total // 3 <= done < total:
            raise Stop

    cut = tmp_path / "cut"
    with pytest.raises(Stop):
        hexmss.run(scene, out=cut, progress=stop)
    assert (cut / "checkpoint.mss").exists()
    resumed = hexmss.run(scene, out=cut, resume=True)
    assert physics(resumed) == physics(reference)
    names = sorted(p.name for p in whole.iterdir())
    assert sorted(p.name for p in cut.iterdir()) == names
    for name in names:
        if name != "summary.json":
            assert (cut / name).read_bytes() == (whole / name).read_bytes(), name
    with pytest.raises(hexmss.SceneError, match="cannot resume"):
        hexmss.run(scene, out=cut, resume=True)
