"""Exceptions for problems a user can fix.

The library raises these; the command line turns each into one line on
stderr and a non-zero exit code, never a traceback.  Anything else that
escapes is a bug in cutkit.
"""

__all__ = [
    "CutkitError",
    "InputError",
    "ModelFormatError",
    "MeshError",
    "EmptySegmentationError",
    "TrajectoryError",
    "ProtocolError",
]


class CutkitError(Exception):
    """Base class: a problem with the user's input, files or settings.

    ``str(err)`` is a single line that names the problem.
    """

    exit_code = 2


class InputError(CutkitError):
    """A missing, unreadable or invalid input file or argument."""


class ModelFormatError(CutkitError):
    """A model file that is corrupt, truncated, of the wrong schema version or inconsistent."""


class MeshError(CutkitError):
    """A mesh that is not a valid tetrahedral mesh (wrong cell type, bad indices, ...)."""


class EmptySegmentationError(CutkitError):
    """A segmentation that selects no voxel."""


class TrajectoryError(CutkitError):
    """A trajectory file with a bad header or row."""


class ProtocolError(CutkitError):
    """A malformed haptics network frame."""
