"""Exceptions raised by hexmss.

Every error of the library arrives as one of these, with the one-line
message the ``mss`` command line prints (naming the file, line, key or value
concerned and what to change). All derive from :class:`HexmssError`; each
also derives from the built-in exception a Python program would expect.
"""

__all__ = [
    "HexmssError",
    "SceneError",
    "MeshError",
    "VoxelizeError",
    "ModelError",
    "SolverError",
    "DivergedError",
    "MechanismError",
    "OutputError",
    "ResourceError",
]


class HexmssError(Exception):
    """Base class of every hexmss error."""


class SceneError(HexmssError, ValueError):
    """A scene (file, dict or TOML text) or a keyword value is refused."""


class MeshError(HexmssError, ValueError):
    """A mesh file cannot be read, or the mesh is malformed."""


class VoxelizeError(HexmssError, ValueError):
    """A mesh cannot be voxelized at the resolution asked for."""


class ModelError(HexmssError, ValueError):
    """A material, model or problem cannot be built, or a dynamic run was
    refused up front because the chosen model would fold under the scene's
    load (``[solver] accept_unstable = true`` runs it anyway)."""


class SolverError(HexmssError, RuntimeError):
    """A solver failed."""


class DivergedError(SolverError):
    """A run diverged (inverted cells, non-finite values, Newton failed, a
    load limit); the state was kept at the last good step."""


class MechanismError(SolverError):
    """Zero-energy motions that the loads excite, or an unstable equilibrium:
    no unique static answer."""


class OutputError(HexmssError, OSError):
    """An output file or folder cannot be written."""


class ResourceError(HexmssError, MemoryError):
    """The job is estimated above the memory limit or the free disk space."""
