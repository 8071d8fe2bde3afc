"""Voxelize the Stanford bunny, let it sag under gravity, report, plot.

    python python/examples/sag.py [--cells 24] [--duration 1.0] [--plot sag.png]

The bunny (data/meshes/bunny.obj, Y up, about 9.66 units tall) is turned Z
up and scaled to 0.15 m, voxelized, given soft-tissue properties (E = 10 kPa,
nu = 0.45, 1000 kg/m^3), held by its lowest tenth (as if glued into a
cup) and left to sag with mass damping. Prints the model, the top's
displacement over time and the static equilibrium it settles to; with
matplotlib installed, saves a plot of the top's displacement against time.

(Held by its lowest layer of nodes alone, the few cells under the bunny's
feet carry all its weight at a stress near E: they are crushed and the
bunny slumps over; `hexmss.solve_static` says so, as a load limit.)
"""

import argparse
import pathlib
import time

import numpy as np

import hexmss

HERE = pathlib.Path(__file__).resolve().parent
BUNNY = HERE.parents[1] / "data" / "meshes" / "bunny.obj"
HEIGHT = 0.15  # m
BUNNY_UNITS_TALL = 9.657897


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=24, help="cells along the longest axis")
    ap.add_argument("--duration", type=float, default=1.0, help="simulated time (s)")
    ap.add_argument("--frames", type=int, default=50, help="samples of the top's motion")
    ap.add_argument("--plot", default="sag.png", help="plot file (needs matplotlib)")
    args = ap.parse_args()

    mesh = hexmss.load_mesh(BUNNY, up="y", scale=HEIGHT / BUNNY_UNITS_TALL)
    lattice = hexmss.voxelize(mesh, cells=args.cells)
    model = hexmss.Model(lattice, hexmss.Material(young=1.0e4, poisson=0.45, density=1000.0))
    problem = hexmss.Problem(
        model,
        fixed=[{"kind": "box", "min": [0, 0, 0], "max": [1, 1, 0.1], "relative": True}],
        gravity=[0.0, 0.0, -9.81],
        damping=8.0,
    )
    print(f"{mesh}\n{lattice}\n{model}\n{problem}")

    # The node highest up at rest: how far the top sinks.
    top = int(np.argmax(lattice.nodes[:, 2]))
    state = hexmss.State(problem)
    integrator = hexmss.Integrator(problem, "explicit")
    steps = max(1, round(args.duration / integrator.dt))
    frames = min(args.frames, steps)
    times, sag = [0.0], [0.0]
    x = np.empty((lattice.num_nodes, 3))  # reused: no allocation per frame
    start = time.perf_counter()
    for k in range(frames):
        integrator.step(state, n=(k + 1) * steps // frames - k * steps // frames)
        state.positions_into(x)
        times.append(state.time)
        sag.append(x[top, 2] - lattice.nodes[top, 2])
    seconds = time.perf_counter() - start

    u = state.displacements(model)
    inverted = model.inverted_cells(state.x)
    print(
        f"t = {state.time:.3f} s in {seconds:.2f} s "
        f"({steps} explicit steps of {integrator.dt:.3e} s)"
    )
    print(f"top node {top}: sank {-sag[-1] * 1000:.2f} mm; largest displacement {np.abs(u).max() * 1000:.2f} mm")
    print(f"inverted cells: {len(inverted)}")
    equilibrium, info = hexmss.solve_static(problem)
    static_sag = equilibrium.x[top, 2] - lattice.nodes[top, 2]
    print(
        f"static equilibrium: top sinks {-static_sag * 1000:.2f} mm "
        f"({info['newton_iterations']} Newton iterations, stable: {info['stable']})"
    )

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(times, np.array(sag) * 1000, label="explicit, damped")
    ax.axhline(static_sag * 1000, color="k", ls="--", lw=0.8, label="static equilibrium")
    ax.legend()
    ax.set_xlabel("time (s)")
    ax.set_ylabel("vertical displacement of the top (mm)")
    ax.set_title(f"Stanford bunny, E = 10 kPa, nu = 0.45, {lattice.num_cells} cells")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.plot, dpi=120)
    print(f"plot: {args.plot}")


if __name__ == "__main__":
    main()
