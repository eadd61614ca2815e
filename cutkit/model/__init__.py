"""The tetrahedral tissue model: what the build writes and the runtime reads.

See :mod:`cutkit.model.tetmodel` for the containers and
:mod:`cutkit.io.model_h5` for the one place the file layout is defined.
"""

from cutkit.model.tetmodel import (
    MATERIAL_FIELDS,
    BoundaryConditions,
    Materials,
    Prestress,
    TetModel,
    Texture,
)

__all__ = [
    "MATERIAL_FIELDS",
    "BoundaryConditions",
    "Materials",
    "Prestress",
    "TetModel",
    "Texture",
]
