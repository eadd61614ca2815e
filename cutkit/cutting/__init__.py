"""Kinematic cutting of tetrahedral models (paper sections 3 and 4.2)."""

from cutkit.cutting.cutmesh import EDGE_SNAP, FACE_BARY_MIN, TET_BARY_MIN, CutMesh
from cutkit.cutting.splits import COMPACT_VOL_MIN
from cutkit.cutting.export import compact_nodes, to_model
from cutkit.cutting.rebase import cut_surface_faces
from cutkit.cutting.step import (StepResult, blade_in_tissue, cut_step, find_trajectory_tetra, finish_stroke,
                                 rebase_if_left, surface_bvh, tet_containing)

__all__ = ["CutMesh", "cut_step", "StepResult", "find_trajectory_tetra", "finish_stroke", "rebase_if_left",
           "blade_in_tissue", "EDGE_SNAP", "FACE_BARY_MIN", "TET_BARY_MIN", "COMPACT_VOL_MIN", "cut_surface_faces",
           "to_model", "compact_nodes", "surface_bvh", "tet_containing"]
