"""Surface collision detection between the scalpel and the tissue (paper section 4.1)."""

from cutkit.collision.bvh import (
    DEFAULT_S_TOL,
    HIT_COPLANAR,
    HIT_EDGE,
    HIT_FACE,
    HIT_VERTEX,
    SegmentHits,
    SurfaceBVH,
)
from cutkit.collision.swept import Contact, blade_entry, query_triangle, swept_faces

__all__ = [
    "DEFAULT_S_TOL",
    "HIT_FACE",
    "HIT_EDGE",
    "HIT_VERTEX",
    "HIT_COPLANAR",
    "SegmentHits",
    "SurfaceBVH",
    "Contact",
    "blade_entry",
    "query_triangle",
    "swept_faces",
]
