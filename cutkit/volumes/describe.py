"""A plain-dict summary of a volume (for ``cutkit info`` and reports)."""

from __future__ import annotations

import numpy as np

from cutkit.volumes.volume import Volume

#: Integer volumes with at most this many distinct values are listed label by label.
MAX_LISTED_LABELS = 256


def describe_volume(volume: Volume) -> dict:
    """Summarise ``volume``.

    Returns
    -------
    dict
        ``dims`` [nx, ny, nz], ``spacing`` [mm], ``origin`` [mm],
        ``direction`` (3x3 nested lists, columns = axes), ``dtype``,
        ``channels``, ``extent_mm`` (world size of the voxel grid),
        ``voxel_mm3``, ``value_range`` [min, max] over finite values,
        ``n_nan``; for integer scalar volumes ``labels``: a list of
        ``{"label", "voxels", "mm3"}`` (or None when there are more than
        ``MAX_LISTED_LABELS`` values).
    """
    data = np.asarray(volume.data)
    voxel_mm3 = float(np.prod(volume.spacing))
    finite = data[np.isfinite(data)] if np.issubdtype(data.dtype, np.floating) else data
    out = {
        "dims": list(volume.shape),
        "spacing": [float(s) for s in volume.spacing],
        "origin": [float(o) for o in volume.origin],
        "direction": volume.direction.tolist(),
        "dtype": str(data.dtype),
        "channels": volume.n_channels,
        "extent_mm": [float(n * s) for n, s in zip(volume.shape, volume.spacing)],
        "voxel_mm3": voxel_mm3,
        "value_range": [float(finite.min()), float(finite.max())] if finite.size else [None, None],
        "n_nan": int(np.count_nonzero(np.isnan(data))) if np.issubdtype(data.dtype, np.floating) else 0,
        "labels": None,
    }
    if data.ndim == 3 and np.issubdtype(data.dtype, np.integer):
        values, counts = np.unique(data, return_counts=True)
        if len(values) <= MAX_LISTED_LABELS:
            out["labels"] = [
                {"label": int(v), "voxels": int(c), "mm3": float(c) * voxel_mm3} for v, c in zip(values, counts)
            ]
    return out
