"""Marching isovolume: a scalar field or label map -> a tetrahedral model (paper section 7.1)."""

from cutkit.isovolume.isovolume import SNAP_FRACTION, IsovolumeStats, isovolume
from cutkit.isovolume.quality import dihedral_summary

__all__ = ["SNAP_FRACTION", "IsovolumeStats", "isovolume", "dihedral_summary"]
