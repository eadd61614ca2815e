"""Six-tetrahedra marching isovolume (paper section 7.1).

"We subdivided each volume cell into six tetrahedra. The volume was then
extracted and tetrahedralized by a marching tetrahedron-type isovolume
algorithm."  Every cube of eight samples is split into the six Kuhn
tetrahedra around its main diagonal; each tetrahedron is clipped at the
iso-level (scalar fields) or between its labels (label maps); the clipped
prisms and pyramids are split into tetrahedra so that both sides of every
quadrilateral agree.  The kernels are in :mod:`cutkit.isovolume._kernels`;
docs/isovolume.md describes the rules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.errors import EmptySegmentationError, InputError
from cutkit.isovolume import _kernels as K
from cutkit.isovolume._crossings import label_crossing_params
from cutkit.isovolume._structs import Crossings, Field
from cutkit.model.tetmodel import TetModel
from cutkit.volumes.volume import Volume

#: A crossing closer than this fraction of its grid edge to a grid vertex
#: snaps to that vertex (the vertex value is taken as the level), so no
#: clipped piece is thinner than this fraction of a cube.
SNAP_FRACTION = 0.15


@dataclass
class IsovolumeStats:
    """What :func:`isovolume` made (also stored in the model's provenance).

    Attributes
    ----------
    mode : str
        ``"scalar"`` or ``"labels"``.
    n_grid_nodes, n_crossing_nodes, n_centre_nodes : int
        Output nodes that are grid samples, edge crossings and tet centres.
    n_snapped : int
        Grid vertices moved onto the level by the snapping rule.
    """

    mode: str
    n_grid_nodes: int
    n_crossing_nodes: int
    n_centre_nodes: int
    n_snapped: int


def _affine(volume: Volume) -> np.ndarray:
    a = np.empty((3, 4), np.float64)
    a[:, :3] = volume.direction * volume.spacing[None, :]
    a[:, 3] = volume.origin
    return a


def isovolume(volume: Volume, level: float = 0.5, labels=None, snap: float = SNAP_FRACTION,
              return_stats: bool = False):
    """Tetrahedralise the inside of a scalar field or the tissues of a label map.

    Parameters
    ----------
    volume : cutkit.volumes.Volume
        ``data`` (nx, ny, nz).  A float array is a scalar field: the region
        ``value >= level`` is meshed.  A bool or integer array is a label map:
        0 is background, every other value a tissue; tissues meet along
        shared (conforming) interfaces through the midpoints of the grid
        edges between two labels.
    level : float
        Iso-level of a scalar field.  Label maps use indicator functions cut
        at 0.5 (edge midpoints) and require ``level`` to be 0.5.
    labels : int or sequence of int, optional
        Scalar field: the label the tets get (default 1).  Label map: the
        tissue labels to mesh (default: every label > 0); others count as
        background.
    snap : float
        Snapping fraction in [0, 0.5): crossings closer than ``snap`` times
        their edge to a grid vertex move onto it (scalar fields; label-map
        crossings are midpoints and never snap).
    return_stats : bool
        Also return an :class:`IsovolumeStats`.

    Returns
    -------
    model : cutkit.model.TetModel
        ``points`` (n, 3) float64 in world mm (the volume's spacing, origin and
        direction), ``tets`` (m, 4) int64 positively oriented, ``labels`` (m,)
        int32.
    stats : IsovolumeStats
        Only with ``return_stats=True``.

    Raises
    ------
    InputError
        Bad volume, level, snap or labels.
    EmptySegmentationError
        Nothing to mesh.
    """
    if not isinstance(volume, Volume):
        raise InputError(f"isovolume: expected a cutkit.volumes.Volume, got {type(volume).__name__}")
    data = np.asarray(volume.data)
    if data.ndim != 3:
        raise InputError(f"isovolume: the volume must be 3D with one channel, got data of shape {data.shape}")
    if min(data.shape) < 2:
        raise InputError(f"isovolume: the volume needs at least 2 samples along each axis, got shape {data.shape}")
    if not (0.0 <= float(snap) < 0.5):
        raise InputError(f"isovolume: snap must be in [0, 0.5), got {snap}")
    if not np.all(np.isfinite(volume.spacing)) or np.any(volume.spacing <= 0):
        raise InputError(f"isovolume: voxel spacing must be positive, got {volume.spacing.tolist()}")
    affine = _affine(volume)
    det = float(np.linalg.det(affine[:, :3]))
    if det == 0.0 or not np.isfinite(det):
        raise InputError("isovolume: the volume's direction matrix is singular")
    sgn = 1.0 if det > 0 else -1.0  # a left-handed frame mirrors every tet
    nx, ny, nz = data.shape
    n_grid = nx * ny * nz
    level = float(level)

    if data.dtype.kind in "biu":
        mode = K.MODE_LABELS
        if level != 0.5:
            raise InputError(f"isovolume: a label map is cut at the edge midpoints (level 0.5), got level {level}")
        if data.dtype.kind != "b" and data.size and (data.min() < 0 or data.max() > np.iinfo(np.int32).max):
            raise InputError("isovolume: label values must be in [0, 2^31), "
                             f"got [{int(data.min())}, {int(data.max())}]")
        lab = np.ascontiguousarray(data, dtype=np.int32).reshape(-1)
        if labels is not None:
            keep = np.atleast_1d(np.asarray(labels, np.int64))
            if np.any(keep <= 0):
                raise InputError(f"isovolume: tissue labels must be > 0, got {keep.tolist()}")
            present = np.unique(lab)
            present = present[present > 0]
            absent = np.setdiff1d(keep, present)
            if absent.size:
                s = "s" * (absent.size > 1)
                raise EmptySegmentationError(
                    f"isovolume: no voxel has label{s} {', '.join(str(int(v)) for v in absent)}; the label map has "
                    + (f"label{'s' * (present.size > 1)} {', '.join(str(int(v)) for v in present)}"
                       if present.size else "no voxel with a label > 0"))
            lab = np.where(np.isin(lab, keep), lab, 0).astype(np.int32)
        on = np.zeros(n_grid, np.uint8)
        f = np.zeros(1, np.float64)
        n_snapped = 0
    elif data.dtype.kind == "f":
        mode = K.MODE_SCALAR
        if not np.isfinite(level):
            raise InputError(f"isovolume: level must be finite, got {level}")
        f = np.ascontiguousarray(data, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(f)):
            raise InputError("isovolume: the scalar field has NaN or infinite samples")
        label = 1 if labels is None else np.atleast_1d(np.asarray(labels, np.int64))
        if not np.isscalar(label):
            if label.size != 1 or label[0] <= 0:
                raise InputError(f"isovolume: a scalar field takes one tissue label > 0, got {label.tolist()}")
            label = int(label[0])
        lab = np.empty(n_grid, np.int32)
        on = np.empty(n_grid, np.uint8)
        K.classify_scalar(f, nx, ny, nz, level, float(snap), np.int32(label), lab, on)
        n_snapped = int(np.count_nonzero(on & (f != level)))
    else:
        raise InputError(f"isovolume: unsupported volume dtype {data.dtype} (need float, integer or bool)")

    mask = np.empty(n_grid, np.uint8)
    K.edge_masks(lab, on, nx, ny, nz, mask)
    n_tets_slab = np.empty(nx - 1, np.int64)
    n_centres_slab = np.empty(nx - 1, np.int64)
    used = np.zeros(n_grid, np.uint8)
    field = Field(lab, on, f, level, mode, sgn)
    K.count_pieces(field, (nx, ny, nz), (n_tets_slab, n_centres_slab), used)
    n_tets = int(n_tets_slab.sum())
    if n_tets == 0:
        what = f"no sample at or above level {level:g}" if mode == K.MODE_SCALAR else "no voxel with a tissue label > 0"
        raise EmptySegmentationError(f"isovolume: nothing to mesh, {what}")

    # Node ids: used grid vertices, then crossings (by vertex, then edge
    # direction), then tet centres (by slab) - each found by a prefix sum.
    vmap = np.cumsum(used, dtype=np.int64) - 1
    n_v = int(vmap[-1]) + 1
    counts = K.POPCOUNT[mask]
    eoff = np.cumsum(counts) - counts + n_v
    n_e = int(counts.sum())
    n_c = int(n_centres_slab.sum())
    tet_off = np.cumsum(n_tets_slab) - n_tets_slab
    centre_off = np.cumsum(n_centres_slab) - n_centres_slab + (n_v + n_e)

    points = np.empty((n_v + n_e + n_c, 3), np.float64)
    tets = np.empty((n_tets, 4), np.int64)
    tet_labels = np.empty(n_tets, np.int32)
    cross_s = np.full(n_e if mode == K.MODE_LABELS else 0, 0.5)
    if mode == K.MODE_LABELS:
        label_crossing_params(lab, mask, eoff, n_v, nx, ny, nz, cross_s)
    crossings = Crossings(mask, eoff, n_v, cross_s)
    K.fill_points(field, crossings, used, vmap, (nx, ny, nz), affine, points)
    K.fill_pieces(field, crossings, vmap, (tet_off, centre_off), (nx, ny, nz), affine, (tets, tet_labels, points))

    stats = IsovolumeStats(
        mode="scalar" if mode == K.MODE_SCALAR else "labels",
        n_grid_nodes=n_v,
        n_crossing_nodes=n_e,
        n_centre_nodes=n_c,
        n_snapped=n_snapped,
    )
    model = TetModel.from_arrays(points, tets, tet_labels)
    model.provenance = {
        "stages": {
            "isovolume": {
                "mode": stats.mode,
                "level": level,
                "snap": float(snap),
                "labels": None if labels is None else np.atleast_1d(labels).astype(int).tolist(),
                "grid_shape": [int(nx), int(ny), int(nz)],
                "split": "kuhn-6",
                "quad_rule": "min-node-diagonal",
            }
        }
    }
    if return_stats:
        return model, stats
    return model
