"""Type stubs of the extension module (re-exported by ``hexmss``).

Units are SI: positions in m, time in s, mass in kg, forces in N, moduli in
Pa, densities in kg/m^3. Arrays out are C-contiguous; positions are float64
``(n, 3)``, indices uint32. Array arguments take anything numpy converts.
"""

import os
from typing import Any, Callable, Literal, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, os.PathLike[str]]
Points = npt.ArrayLike
"""An (n, 3) array-like of coordinates (m)."""
FloatArray = npt.NDArray[np.float64]
IndexArray = npt.NDArray[np.uint32]
Progress = Callable[[str, int, int], Any]
"""``progress(stage, done, total)``: stage is "voxelizing", "solving" or "stepping"."""
SceneLike = Union["Scene", Mapping[str, Any], PathLike]
"""A Scene, a dict with a scene file's tables, or the path of a scene file."""

def set_threads(n: Optional[int] = None) -> None:
    """Worker threads of later calls (None: one per core). Results do not depend on it."""

def get_threads() -> int:
    """The number of worker threads calls run on."""

class Mesh:
    """A closed triangle surface (m): what is voxelized."""

    def __init__(self, vertices: Points, triangles: npt.ArrayLike, name: str = "arrays") -> None:
        """A mesh from (n, 3) vertex positions (m) and (m, 3) vertex indices,
        cleaned as files are (degenerate and repeated triangles dropped)."""
    @property
    def vertices(self) -> FloatArray:
        """Vertex positions (n, 3), read-only, the same array on every access (m)."""
    @property
    def triangles(self) -> IndexArray:
        """Triangles as vertex indices (m, 3), read-only."""
    @property
    def name(self) -> str:
        """Where the mesh came from (a path, ``builtin:NAME`` or ``arrays``)."""
    @property
    def bounds(self) -> tuple[list[float], list[float]]:
        """Bounding box as (min, max) corners (m)."""
    @property
    def volume(self) -> float:
        """Enclosed volume (m^3), positive for outward winding."""
    def place(
        self,
        *,
        units: Literal["m", "cm", "mm"] = "m",
        scale: Union[float, Sequence[float]] = 1.0,
        up: Literal["x", "y", "z"] = "z",
        rotate: Sequence[float] = (0.0, 0.0, 0.0),
        translate: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> "Mesh":
        """A placed copy (the keys of a scene's [mesh] table; rotate in degrees
        about fixed x, y, z; translate in m), applied in that order."""
    def __len__(self) -> int: ...

def load_mesh(
    path: PathLike,
    *,
    units: Literal["m", "cm", "mm"] = "m",
    scale: Union[float, Sequence[float]] = 1.0,
    up: Literal["x", "y", "z"] = "z",
    rotate: Sequence[float] = (0.0, 0.0, 0.0),
    translate: Sequence[float] = (0.0, 0.0, 0.0),
) -> Mesh:
    """Loads OBJ, STL, PLY or VTK (legacy, .vtu, .vtp; format told from the
    content), or "builtin:critter", cleaned and placed."""

def voxelize(
    mesh: Mesh,
    *,
    progress: Optional[Progress] = None,
    cells: Optional[int] = None,
    cell_size: Optional[float] = None,
    rule: Literal["centre", "any", "fraction"] = "centre",
    fraction: float = 0.5,
    components: Literal["largest", "all"] = "largest",
    max_cells: int = 10_000_000,
) -> "Lattice":
    """The cubic lattice of a mesh (the keys of a scene's [voxelize] table):
    ``cells`` along the longest axis (default 24) or ``cell_size`` (m)."""

LabelArray = npt.NDArray[np.int32]

class Image:
    """A label volume: one integer label per voxel, and where the voxels are."""

    @property
    def labels(self) -> LabelArray:
        """The labels, indexed labels[i, j, k] (shape (ni, nj, nk)), read-only."""
    @property
    def affine(self) -> FloatArray:
        """4 x 4 voxel-to-world matrix (file units): voxel (i, j, k) is at affine @ (i, j, k, 1)."""
    @property
    def shape(self) -> tuple[int, int, int]:
        """Voxels along i, j, k."""
    @property
    def spacing(self) -> tuple[float, float, float]:
        """Voxel spacing along i, j, k (file units)."""
    @property
    def unit_metres(self) -> Optional[float]:
        """Metres per unit of the world coordinates as the file says, or None (read as mm)."""
    @property
    def space(self) -> str:
        """The frame of the world coordinates: "RAS", "LPS" or the file's name for another."""
    @property
    def name(self) -> str:
        """The file it was read from."""
    def label_counts(self) -> dict[int, int]:
        """The number of voxels of each label."""

def load_image(path: PathLike) -> Image:
    """Reads a label image: NIfTI-1/-2 (.nii, .nii.gz, .hdr/.img) or NRRD (.nrrd, .nhdr)."""

class ImageLattice:
    """The lattice of a label image, the label of each cell and the labels' surface."""

    @property
    def lattice(self) -> "Lattice":
        """The cubic lattice."""
    @property
    def cell_labels(self) -> LabelArray:
        """The label covering most of each cell, (C,)."""
    @property
    def surface(self) -> Mesh:
        """The chosen labels' boundary (m)."""
    @property
    def voxels_per_label(self) -> dict[int, int]:
        """Voxels of each chosen label."""

def voxelize_image(
    path: PathLike,
    *,
    labels: Optional[Sequence[int]] = None,
    threshold: float = 0.5,
    units: Optional[Literal["m", "cm", "mm"]] = None,
    space: Literal["file", "RAS", "LPS"] = "file",
    rotate: Sequence[float] = (0.0, 0.0, 0.0),
    translate: Sequence[float] = (0.0, 0.0, 0.0),
    cells: Optional[int] = None,
    cell_size: Optional[float] = None,
    components: Literal["largest", "all"] = "largest",
    max_cells: int = 10_000_000,
) -> ImageLattice:
    """The chosen labels of a label image resampled to cubes (the keys of a
    scene's [image] and [voxelize] tables)."""

class Lattice:
    """A cubic lattice of cells (hexahedra) and their corner nodes."""

    @staticmethod
    def block(n: Sequence[int], h: float, origin: Sequence[float] = (0.0, 0.0, 0.0)) -> "Lattice":
        """A box of n = (nx, ny, nz) cells of edge h (m) from origin (m)."""
    @property
    def nodes(self) -> FloatArray:
        """Rest positions (N, 3), read-only (m)."""
    @property
    def cells(self) -> IndexArray:
        """Corner nodes of each cell (C, 8), read-only, VTK_HEXAHEDRON order."""
    @property
    def cell_coords(self) -> IndexArray:
        """Integer grid coordinates of each cell (C, 3)."""
    @property
    def node_coords(self) -> IndexArray:
        """Integer grid coordinates of each node (N, 3)."""
    @property
    def h(self) -> float:
        """Cell edge (m)."""
    @property
    def origin(self) -> list[float]:
        """Position of grid node (0, 0, 0) (m)."""
    @property
    def dims(self) -> list[int]:
        """Grid dimensions in cells."""
    @property
    def num_nodes(self) -> int: ...
    @property
    def num_cells(self) -> int: ...
    @property
    def volume(self) -> float:
        """Volume of the cells (m^3)."""
    def skin(self) -> "Skin":
        """The boundary faces as triangles bound to nodes."""
    def embed(self, mesh: Mesh) -> "Embedding":
        """Binds each vertex of ``mesh`` to its cell (trilinear weights)."""

class Skin:
    """The lattice's boundary as triangles whose vertices follow nodes."""

    @property
    def vertex_nodes(self) -> IndexArray:
        """The node each skin vertex follows (V,)."""
    @property
    def triangles(self) -> IndexArray:
        """Triangles as skin vertex indices (T, 3), outward."""
    def positions(self, node_positions: Points) -> FloatArray:
        """Skin vertex positions (V, 3) for node positions (N, 3) (m)."""

class Embedding:
    """A surface embedded in a lattice: it moves trilinearly with its cells."""

    @property
    def triangles(self) -> IndexArray: ...
    def deform(self, node_positions: Points) -> FloatArray:
        """Surface vertex positions (V, 3) for node positions (N, 3) (m)."""

class Material:
    """An isotropic linear elastic material."""

    def __init__(self, young: float, poisson: float, density: float) -> None:
        """Young's modulus E (Pa), Poisson's ratio nu, density (kg/m^3)."""
    @property
    def young(self) -> float: ...
    @property
    def poisson(self) -> float: ...
    @property
    def density(self) -> float: ...
    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) (Pa)."""
    @property
    def lame_lambda(self) -> float:
        """Lame's first parameter (Pa)."""
    @property
    def bulk_modulus(self) -> float:
        """K (Pa)."""

def parameterizations() -> list[str]:
    """Parameterization names a Model accepts (each also with "+hg")."""

def integrators() -> list[str]:
    """Integrator names an Integrator accepts."""

class Model:
    """A lattice turned into a mass-spring model."""

    def __init__(
        self,
        lattice: Lattice,
        material: Material,
        parameterization: Optional[str] = None,
        hourglass: Optional[float] = None,
    ) -> None:
        """``parameterization``: one of parameterizations(), optionally "+hg",
        read as a scene's [model] table (``hourglass``: the factor of
        hourglass control, dimensionless; "+hg" alone gets 0.05). Without
        one: the bundled default scene's "volumetric-barrier+hg" with
        hourglass 1.0."""
    @property
    def dimension(self) -> int:
        """3 (a PlaneModel's is 2)."""
    @property
    def masses(self) -> FloatArray:
        """Node masses (N,) (kg)."""
    @property
    def rest_positions(self) -> FloatArray:
        """(N, 3) (m)."""
    @property
    def num_nodes(self) -> int: ...
    @property
    def num_cells(self) -> int: ...
    @property
    def num_springs(self) -> int: ...
    @property
    def total_mass(self) -> float:
        """(kg)."""
    @property
    def h(self) -> float:
        """Cell edge (m)."""
    @property
    def parameterization(self) -> str: ...
    @property
    def stable_time_step(self) -> float:
        """Stable explicit step of the undamped model at rest (s)."""
    def internal_forces(self, x: Points, out: Optional[FloatArray] = None) -> FloatArray:
        """Internal forces (N, 3) at positions x (N); written into ``out``
        (float64, C-contiguous) when given, with no allocation."""
    def energy(self, x: Points) -> float:
        """Energy of the springs and the volumetric term (J)."""
    def inverted_cells(self, x: Points) -> list[int]:
        """Cells turned inside out at positions x."""
    def folded_cells(self, x: Points) -> list[int]:
        """Cells folded at a corner (a corner Jacobian <= 0) at positions x."""
    def corner_jacobians(self, x: Points) -> FloatArray:
        """Per cell, the smallest of its 8 corner Jacobians (1 at rest)."""
    def affine_deviation(self, x: Points) -> FloatArray:
        """Per cell, distance of its nodes from the best affine map, / h."""

class RectLattice:
    """Rectangles lx x ly (any aspect ratio) on a grid of the x-y plane,
    for the paper's 2D element."""

    @staticmethod
    def block(n: Sequence[int], cell: Sequence[float], origin: Sequence[float] = (0.0, 0.0)) -> "RectLattice":
        """A block of n = (nx, ny) cells of cell = (lx, ly) m from origin."""
    @staticmethod
    def rasterize(polygons: Sequence[Sequence[Sequence[float]]], cell: Sequence[float]) -> "RectLattice":
        """The cells whose centres lie inside closed polygons of (x, y)
        points (m; even-odd: a polygon inside another is a hole)."""
    @property
    def nodes(self) -> FloatArray:
        """(N, 2) node positions (m)."""
    @property
    def cells(self) -> IndexArray:
        """(C, 4) node indices, counter-clockwise from the lower left."""
    @property
    def cell_size(self) -> tuple[float, float]:
        """(lx, ly) (m)."""
    @property
    def num_nodes(self) -> int: ...
    @property
    def num_cells(self) -> int: ...
    @property
    def area(self) -> float:
        """(m^2)."""

class PlaneModel:
    """The paper's 2D element on a RectLattice (plane stress); positions are
    (N, 3) arrays with z = 0, the methods those of Model."""

    def __init__(
        self,
        lattice: RectLattice,
        material: Material,
        thickness: float,
        parameterization: Optional[str] = None,
        hourglass: Optional[float] = None,
    ) -> None:
        """``thickness`` (m); ``parameterization`` "paper", "springs" or
        "areal", each optionally "+hg" (factor ``hourglass``, default 1);
        None: "paper+hg"."""
    @property
    def dimension(self) -> int:
        """2."""
    @property
    def masses(self) -> FloatArray:
        """Node masses (N,) (kg)."""
    @property
    def rest_positions(self) -> FloatArray:
        """(N, 3) with z = 0 (m)."""
    @property
    def num_nodes(self) -> int: ...
    @property
    def num_cells(self) -> int: ...
    @property
    def total_mass(self) -> float:
        """(kg)."""
    @property
    def cell_size(self) -> tuple[float, float]:
        """(lx, ly) (m)."""
    @property
    def thickness(self) -> float:
        """(m)."""
    @property
    def parameterization(self) -> str: ...
    @property
    def stable_time_step(self) -> float:
        """Stable explicit step of the undamped model at rest (s)."""
    def internal_forces(self, x: Points) -> FloatArray:
        """Internal forces (N, 3) at positions x (N; z = 0)."""
    def energy(self, x: Points) -> float:
        """Elastic energy (J)."""

class PlaneProblem:
    """A PlaneModel with held nodes, in-plane loads and damping; the
    keywords take a 2D scene's tables."""

    def __init__(
        self,
        model: PlaneModel,
        *,
        fixed: Optional[Sequence[Mapping[str, Any]]] = None,
        gravity: Optional[Sequence[float]] = None,
        forces: Optional[Sequence[Mapping[str, Any]]] = None,
        tractions: Optional[Sequence[Mapping[str, Any]]] = None,
        drags: Optional[Sequence[Mapping[str, Any]]] = None,
        damping: float = 0.0,
    ) -> None: ...
    @property
    def model(self) -> PlaneModel: ...
    @property
    def held_nodes(self) -> list[int]: ...
    def stable_time_step(self, safety: float = 0.9) -> float:
        """2 / omega_max times ``safety`` (s)."""
    def solve_static(self, x: Optional[Points] = None, time: float = 0.0) -> FloatArray:
        """The static equilibrium from x (default: rest), (N, 3)."""
    def step(
        self,
        x: Points,
        v: Points,
        dt: float,
        n: int = 1,
        t0: float = 0.0,
        implicit: bool = False,
    ) -> tuple[FloatArray, FloatArray]:
        """``n`` explicit (dt stable) or implicit (any dt) steps from (x, v)
        at t0; the new (x, v)."""

class Problem:
    """A model with boundary conditions, loads, damping and obstacles."""

    def __init__(
        self,
        model: Model,
        *,
        fixed: Optional[Sequence[Mapping[str, Any]]] = None,
        gravity: Optional[Sequence[float]] = None,
        forces: Optional[Sequence[Mapping[str, Any]]] = None,
        tractions: Optional[Sequence[Mapping[str, Any]]] = None,
        drags: Optional[Sequence[Mapping[str, Any]]] = None,
        custom_loads: Optional[Sequence[Mapping[str, Any]]] = None,
        motions: Optional[Sequence[Mapping[str, Any]]] = None,
        motion_duration: float = 1.0,
        damping: float = 0.0,
        stiffness_damping: float = 0.0,
        obstacles: Optional[Sequence[Mapping[str, Any]]] = None,
        contact_points: Optional[Literal["nodes", "surface", "both"]] = None,
        surface: Optional[Embedding] = None,
    ) -> None:
        """The keys follow a scene's tables: [[fixed]], [loads] (gravity in
        m/s^2, forces, tractions, drags, and custom_loads: [[loads.custom]]
        tables by ``kind``), [[motions]] (default end
        ``motion_duration``, s), damping alpha (1/s) and beta (s),
        [[obstacles]] and [contact] points."""
    @property
    def model(self) -> Model: ...
    @property
    def num_nodes(self) -> int: ...
    @property
    def num_held_dofs(self) -> int: ...
    @property
    def held_nodes(self) -> list[int]:
        """Fully held nodes."""
    @property
    def stable_time_step(self) -> float:
        """Stable explicit step with damping and contact, safety 1 (s)."""
    def external_forces(self, x: Points, t: float = 0.0) -> FloatArray:
        """Loads at positions x and time t (N), without contact."""
    def contact_forces(self, state: "State") -> FloatArray:
        """Obstacle forces on the nodes (N)."""

class State:
    """Positions, velocities and time of a problem's nodes."""

    def __init__(self, problem: Problem) -> None:
        """The rest state at t = 0 (held nodes on their motion)."""
    x: FloatArray
    """Node positions (N, 3) (m): reading gives a copy; assign to set."""
    v: FloatArray
    """Node velocities (N, 3) (m/s): reading gives a copy; assign to set."""
    time: float
    """(s)."""
    def positions_into(self, out: FloatArray) -> FloatArray:
        """Copies positions into ``out`` without allocating; returns it."""
    def displacements(self, model: Model) -> FloatArray:
        """Positions minus rest positions (N, 3) (m)."""
    def kinetic_energy(self, model: Model) -> float:
        """(J)."""
    def copy(self) -> "State": ...

def solve_static(
    problem: Problem,
    state: Optional[State] = None,
    *,
    rtol: Optional[float] = None,
    max_newton: Optional[int] = None,
    linear: bool = False,
    accept_unstable: bool = False,
    linear_solver: Literal["auto", "direct", "iterative"] = "auto",
    obstacles_from: Optional[float] = None,
) -> tuple[State, dict[str, Any]]:
    """Static equilibrium: (state, info) with newton_iterations, load_steps,
    rejected_iterations, relative_residual, krylov_iterations and stable
    (True, False or None: not tested). ``linear`` solves the small-strain
    problem once. ``obstacles_from``: the time at which ``state`` was in
    equilibrium with the obstacles (0.0 for a body at rest); they are moved
    along their paths from then, as a slow press would. Raises
    MechanismError for zero-energy motions and for an unstable equilibrium
    unless ``accept_unstable``."""

class Integrator:
    """A time integrator bound to a problem."""

    def __init__(
        self,
        problem: Problem,
        kind: str = "explicit",
        *,
        dt: Optional[float] = None,
        safety: Optional[float] = None,
        substep: bool = False,
        rtol: Optional[float] = None,
        max_newton: Optional[int] = None,
        linear_solver: Literal["auto", "direct", "iterative"] = "auto",
        precision: Literal["f64", "f32"] = "f64",
    ) -> None:
        """``kind``: one of integrators(). Explicit schemes step at the stable
        limit times ``safety`` unless ``dt`` (s) is given; ``precision="f32"``
        runs their force pass in single precision."""
    @property
    def dt(self) -> float:
        """(s)."""
    @property
    def name(self) -> str: ...
    def step(self, state: State, n: int = 1) -> dict[str, Any]:
        """Advances ``state`` in place by n steps: {time, steps, substeps,
        newton_iterations}. On DivergedError the state is the last good one."""

class Simulation:
    """An interactive simulation: stepped frame by frame, with a drag."""

    def __init__(self, problem: Problem, surface: Optional[Embedding] = None) -> None:
        """A simulation of a fresh copy of ``problem`` from rest."""
    @property
    def precision(self) -> Literal["f64", "f32"]:
        """Precision of the force pass ("f32": faster, for interactive use)."""
    @precision.setter
    def precision(self, value: Literal["f64", "f32"]) -> None: ...
    def step(self, dt: float) -> int:
        """Advances by dt (s) in as many sub-steps as stability asks; returns them."""
    def settle(
        self, rtol: Optional[float] = None, max_time: Optional[float] = None
    ) -> dict[str, Any]:
        """Brings the bodies to rest under the loads at the current time (a scene's
        ``start = "settled"``); ``steps``, ``settle_time``, ``relative_residual``, ``omega``."""
    @property
    def time(self) -> float:
        """(s)."""
    @property
    def positions(self) -> FloatArray:
        """Node positions (N, 3), a copy (m)."""
    def positions_into(self, out: FloatArray) -> FloatArray:
        """Copies positions into ``out`` without allocating; returns it."""
    @property
    def velocities(self) -> FloatArray:
        """(N, 3) (m/s)."""
    @property
    def state(self) -> State:
        """A copy of the state reached."""
    def nearest_node(self, point: Sequence[float]) -> int: ...
    def pick(self, nodes: Sequence[int], stiffness: float) -> None:
        """Holds nodes by zero-length springs of ``stiffness`` (N/m each)."""
    def drag_to(self, point: Sequence[float]) -> None:
        """Moves the picked nodes' target centroid (m)."""
    def release(self) -> None: ...
    def surface_positions(self) -> FloatArray:
        """Vertex positions of the embedded surface (V, 3) (m)."""

class Scene:
    """A scene: the TOML schema of ``mss run`` (docs/scenes.md)."""

    @staticmethod
    def from_file(path: PathLike) -> "Scene": ...
    @staticmethod
    def from_toml(text: str, name: str = "<toml>") -> "Scene": ...
    @staticmethod
    def from_dict(d: Mapping[str, Any], name: str = "<dict>") -> "Scene": ...
    @staticmethod
    def default() -> "Scene":
        """The bundled default scene (what ``mss run`` runs without arguments)."""
    @property
    def name(self) -> str: ...
    @property
    def duration(self) -> float:
        """(s)."""
    def with_duration(self, seconds: float) -> "Scene": ...
    @property
    def output_folder(self) -> str: ...

class Job:
    """A prepared scene: mesh voxelized, model and problem built."""

    @property
    def mesh(self) -> Mesh:
        """The mesh (the first body's in a scene of [[bodies]])."""
    @property
    def lattice(self) -> Lattice:
        """The lattice (the first body's in a scene of [[bodies]])."""
    @property
    def body_names(self) -> list[str]:
        """The bodies' names, in the order of the model's nodes."""
    @property
    def body_nodes(self) -> list[tuple[int, int]]:
        """Each body's first and one-past-last node: positions[start:end]."""
    @property
    def model(self) -> Model: ...
    @property
    def problem(self) -> Problem: ...
    @property
    def dt(self) -> float:
        """(s)."""
    @property
    def steps(self) -> int: ...
    @property
    def is_static(self) -> bool: ...
    @property
    def stable_time_step(self) -> float:
        """(s)."""
    def run(
        self, out: Optional[PathLike] = None, *, progress: Optional[Progress] = None, resume: bool = False
    ) -> dict[str, Any]:
        """Runs the job into ``out``; returns the summary (summary.json's fields).
        ``resume`` continues the interrupted run in ``out`` from its checkpoint."""
    def simulation(self) -> Simulation:
        """An interactive Simulation of the job's problem and mesh."""

def prepare(
    scene: SceneLike,
    *,
    max_memory: Optional[Union[int, str]] = None,
    progress: Optional[Progress] = None,
) -> Job:
    """Loads, voxelizes and builds a scene, refusing jobs above max_memory
    (bytes or "8GiB"; default 3/4 of the machine's memory)."""

def run(
    scene: SceneLike,
    out: Optional[PathLike] = None,
    *,
    progress: Optional[Progress] = None,
    max_memory: Optional[Union[int, str]] = None,
    resume: bool = False,
) -> dict[str, Any]:
    """Prepares and runs a scene as ``mss run`` does; returns the summary.
    Ctrl-C stops it cleanly (frames and a checkpoint written) and raises
    KeyboardInterrupt; ``resume=True`` continues it in ``out``, ending
    bitwise as an uninterrupted run."""

def write_vtu(
    path: PathLike,
    lattice: Lattice,
    positions: Optional[Points] = None,
    *,
    point_data: Optional[Mapping[str, npt.ArrayLike]] = None,
    cell_data: Optional[Mapping[str, npt.ArrayLike]] = None,
    encoding: Literal["zlib", "base64", "ascii"] = "zlib",
) -> None:
    """Writes the lattice at ``positions`` as .vtu (atomically)."""

def write_obj(
    path: PathLike,
    vertices: Points,
    triangles: npt.ArrayLike,
    *,
    normals: Literal["smooth", "flat"] = "smooth",
) -> None:
    """Writes a triangle surface as Wavefront OBJ (atomically)."""

def write_stl(path: PathLike, vertices: Points, triangles: npt.ArrayLike) -> None:
    """Writes a triangle surface as binary STL (atomically)."""

def view(
    scene_or_path: Union[Scene, PathLike, None] = None,
    port: int = 0,
    open_browser: bool = True,
    host: str = "127.0.0.1",
    paused: bool = False,
) -> str:
    """Starts the live browser viewer of ``mss view`` and returns its
    address with its token: a Scene, a scene file or None (the bundled
    scene) runs live (drag it, poke it); a run's folder is replayed. It
    serves from a background thread until ``stop_views()``."""

def stop_views() -> int:
    """Stops every viewer ``view`` started; returns how many."""
