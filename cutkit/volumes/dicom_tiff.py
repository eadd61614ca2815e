"""Readers of DICOM series (a folder of slices) and TIFF stacks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.volumes.volume import Volume

#: Slices whose gaps differ from the median gap by more than this fraction
#: are reported as an irregular series (a missing slice, two series mixed).
SLICE_GAP_TOLERANCE = 0.05

_TIFF_EXT = (".tif", ".tiff")


def _is_dicom(p: Path) -> bool:
    try:
        with open(p, "rb") as f:
            head = f.read(132)
        return len(head) == 132 and head[128:132] == b"DICM"
    except OSError:
        return False


def folder_kind(path: Path) -> str:
    """'dicom-series' or 'tiff-folder' by what the folder holds."""
    files = sorted(p for p in path.iterdir() if p.is_file())
    if any(_is_dicom(p) or p.suffix.lower() == ".dcm" for p in files):
        return "dicom-series"
    if any(p.suffix.lower() in _TIFF_EXT for p in files):
        return "tiff-folder"
    raise InputError(f"{path}: folder holds no DICOM slices and no TIFF images")


def read_dicom_series(path: Path) -> Volume:
    """Stack the single-frame slices of ``path`` into a volume in LPS mm.

    Slices are sorted by ImagePositionPatient projected on the slice normal
    (row cosine x column cosine); the slice spacing is the median gap
    between those projections (SliceThickness is not a spacing).  Pixel
    values are mapped through RescaleSlope/RescaleIntercept.
    """
    import pydicom

    files = sorted(p for p in path.iterdir() if p.is_file() and (_is_dicom(p) or p.suffix.lower() == ".dcm"))
    slices = [pydicom.dcmread(str(p)) for p in files]
    if not slices:
        raise InputError(f"{path}: no DICOM slices")
    uids = {getattr(s, "SeriesInstanceUID", None) for s in slices}
    if len(uids) > 1:
        raise InputError(f"{path}: folder mixes {len(uids)} DICOM series")
    iop = np.asarray(slices[0].ImageOrientationPatient, float)
    row_cos, col_cos = iop[:3], iop[3:]
    normal = np.cross(row_cos, col_cos)
    pos = np.array([np.asarray(s.ImagePositionPatient, float) for s in slices])
    order = np.argsort(pos @ normal)
    slices = [slices[o] for o in order]
    pos = pos[order]
    proj = pos @ normal
    if len(slices) > 1:
        gaps = np.diff(proj)
        dz = float(np.median(gaps))
        if dz <= 0 or np.max(np.abs(gaps - dz)) > SLICE_GAP_TOLERANCE * dz:
            raise InputError(
                f"{path}: irregular slice positions along the normal (gaps {gaps.min():.3g}..{gaps.max():.3g} mm)"
            )
    else:
        dz = float(getattr(slices[0], "SliceThickness", 1.0) or 1.0)
    ps = [float(v) for v in slices[0].PixelSpacing]  # (row spacing, column spacing)
    planes = []
    scaled = False
    for s in slices:
        a = s.pixel_array
        slope = float(getattr(s, "RescaleSlope", 1.0) or 1.0)
        inter = float(getattr(s, "RescaleIntercept", 0.0) or 0.0)
        if slope != 1.0 or inter != 0.0:
            a = a.astype(np.float32) * slope + inter
            scaled = True
        planes.append(a)
    arr = np.stack(planes, axis=-1)  # [row, column, slice]
    if scaled:
        arr = arr.astype(np.float32)
    # pixel_array[r, c]: c runs along the row cosine, r along the column cosine.
    data = np.swapaxes(arr, 0, 1)
    direction = np.column_stack([row_cos, col_cos, normal])
    spacing = np.array([ps[1], ps[0], dz])
    return Volume(np.ascontiguousarray(data), spacing, pos[0], direction)


def _tiff_to_ijk(arr: np.ndarray) -> np.ndarray:
    """(pages, rows, columns[, 3]) -> [i=column, j=row, k=page(, c)]."""
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim == 4:
        return np.ascontiguousarray(arr.transpose(2, 1, 0, 3))
    if arr.ndim == 3:
        return np.ascontiguousarray(arr.transpose(2, 1, 0))
    raise InputError(f"TIFF data of shape {arr.shape} is not a stack of 2D images")


def read_tiff(path: Path) -> Volume:
    """A multi-page TIFF: page k is the slice k; spacing comes from the caller."""
    import tifffile

    return Volume(_tiff_to_ijk(tifffile.imread(str(path))))


def read_tiff_folder(path: Path) -> Volume:
    """A folder of TIFF images, one slice each, stacked in file-name order."""
    import tifffile

    files = sorted(p for p in path.iterdir() if p.suffix.lower() in _TIFF_EXT)
    planes = [tifffile.imread(str(p)) for p in files]
    shapes = {p.shape for p in planes}
    if len(shapes) != 1:
        raise InputError(f"{path}: TIFF slices differ in shape ({', '.join(map(str, sorted(shapes)))})")
    return Volume(_tiff_to_ijk(np.stack(planes)))
