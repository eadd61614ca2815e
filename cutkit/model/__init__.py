"""The tetrahedral tissue model: what the build writes and the runtime reads.

See :mod:`cutkit.model.tetmodel` for the containers and
:mod:`cutkit.io.model_h5` for the one place the file layout is defined.
"""

from cutkit.model.tetmodel import (
    DEFAULT_MATERIAL_MODEL,
    MATERIAL_FIELDS,
    MATERIAL_MODELS,
    BoundaryConditions,
    Materials,
    Prestress,
    TetModel,
    Texture,
)

__all__ = [
    "DEFAULT_MATERIAL_MODEL",
    "MATERIAL_FIELDS",
    "MATERIAL_MODELS",
    "BoundaryConditions",
    "Materials",
    "Prestress",
    "TetModel",
    "Texture",
]
