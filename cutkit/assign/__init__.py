"""Material, boundary-condition and prestress assignment (paper section 7.3)."""

from cutkit.assign.assign import assign, region_nodes
from cutkit.assign.defaults import DEFAULT_MATERIALS

__all__ = ["assign", "region_nodes", "DEFAULT_MATERIALS"]
