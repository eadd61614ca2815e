"""Progressive tetrahedral decimation (paper section 7.1; Staadt and Gross 1998).

``decimate(model, target_tets=... | ratio=...)`` collapses edges, interior
first, and records the collapses in ``model.extra["progressive"]``;
``extract_level(model, k)`` rebuilds the mesh after the first ``k`` collapses.
"""

from cutkit.decimate.decimate import decimate, min_dihedral_deg, quality_summary, reference_length
from cutkit.decimate.progressive import RECORD, extract_level, n_levels, replay

__all__ = ["decimate", "extract_level", "n_levels", "replay", "reference_length", "min_dihedral_deg", "quality_summary", "RECORD"]
