"""hexmss: hexahedral mass-spring soft bodies (Baudet et al., WSCG 2009).

Turn a surface mesh into a physically parameterized soft body: give Young's
modulus E (Pa), Poisson's ratio nu and a density (kg/m^3), and simulate it
statically, with an explicit or implicit integrator, or interactively.
Units are SI throughout (m, s, kg, N, Pa).

Two ways in:

- scenes, as the ``mss`` command line runs them::

      import hexmss
      summary = hexmss.run("data/scenes/default.toml", out="out")

- the library, with numpy arrays in and out::

      mesh = hexmss.load_mesh("bunny.obj", units="m", up="y")
      lattice = hexmss.voxelize(mesh, cells=24)
      model = hexmss.Model(lattice, hexmss.Material(2e4, 0.3, 1000.0))
      problem = hexmss.Problem(model, fixed=[{"kind": "lowest_layer"}],
                               gravity=[0, 0, -9.81], damping=8.0)
      state = hexmss.State(problem)
      hexmss.Integrator(problem, "explicit").step(state, n=100)

- the paper's 2D element (plane stress, rectangles of any aspect ratio)::

      lattice = hexmss.RectLattice.block((8, 2), (0.02, 0.01))
      model = hexmss.PlaneModel(lattice, hexmss.Material(1e6, 0.3, 1000.0), thickness=0.01)
      problem = hexmss.PlaneProblem(model, fixed=[{"kind": "face", "face": "x-"}],
                                    gravity=[0, -9.81, 0])
      x = problem.solve_static()

- segmented images (NIfTI, NRRD) instead of meshes::

      image = hexmss.load_image("seg.nii.gz")        # labels, affine
      body = hexmss.voxelize_image("seg.nii.gz", labels=[1, 2], cells=24)
      body.lattice, body.cell_labels, body.surface

Long calls release the GIL and take an optional ``progress(stage, done,
total)`` callback; ``set_threads`` chooses the worker threads (results do
not depend on it). Errors are the exceptions of :mod:`hexmss.errors`.
"""

from . import errors
from ._hexmss import (
    Embedding,
    Image,
    ImageLattice,
    Integrator,
    Job,
    Lattice,
    Material,
    Mesh,
    Model,
    PlaneModel,
    PlaneProblem,
    Problem,
    RectLattice,
    Scene,
    Simulation,
    Skin,
    State,
    __version__,
    get_threads,
    integrators,
    load_image,
    load_mesh,
    parameterizations,
    prepare,
    run,
    set_threads,
    solve_static,
    stop_views,
    view,
    voxelize,
    voxelize_image,
    write_obj,
    write_stl,
    write_vtu,
)
from .errors import (
    DivergedError,
    HexmssError,
    MechanismError,
    MeshError,
    ModelError,
    OutputError,
    ResourceError,
    SceneError,
    SolverError,
    VoxelizeError,
)

__all__ = [
    "DivergedError",
    "Embedding",
    "HexmssError",
    "Image",
    "ImageLattice",
    "Integrator",
    "Job",
    "Lattice",
    "Material",
    "MechanismError",
    "Mesh",
    "MeshError",
    "Model",
    "ModelError",
    "OutputError",
    "PlaneModel",
    "PlaneProblem",
    "Problem",
    "RectLattice",
    "ResourceError",
    "Scene",
    "SceneError",
    "Simulation",
    "Skin",
    "SolverError",
    "State",
    "VoxelizeError",
    "__version__",
    "errors",
    "get_threads",
    "integrators",
    "load_image",
    "load_mesh",
    "parameterizations",
    "prepare",
    "run",
    "set_threads",
    "solve_static",
    "stop_views",
    "view",
    "voxelize",
    "voxelize_image",
    "write_obj",
    "write_stl",
    "write_vtu",
]
