"""Turn a scalar, RGB or label volume into a uint8 label map.

The entry point :func:`segment` composes small steps, each usable alone:

1. :func:`scalar_channel` -- one float image (a colour channel of RGB data);
2. :func:`smooth_mm` -- Gaussian smoothing with sigma in mm;
3. :func:`resample_isotropic` -- resampling onto cubic voxels;
4. :func:`threshold_mask` / :func:`otsu_threshold` -- the foreground mask;
5. :func:`clean_mask`, :func:`largest_connected_component`, :func:`fill_mask_holes`.

Colour data: the Visible Human cryosections the paper segments show the
limb against a blue background (paper section 7.1), so on the blue channel
tissue is the *dark* side.  With ``channel='b'`` and no explicit
threshold, Otsu's threshold is computed on the blue channel and voxels
*below* it are kept; on every other image Otsu keeps the bright side.
"""

from __future__ import annotations

import numpy as np

from cutkit.errors import EmptySegmentationError, InputError
from cutkit.volumes.volume import Volume

#: Radius (voxels) of the ball used by the opening/closing clean-up.
CLEAN_BALL_RADIUS_VOXELS = 1

_CHANNELS = {"r": 0, "red": 0, "g": 1, "green": 1, "b": 2, "blue": 2}


def _channel_index(channel) -> int:
    if isinstance(channel, (int, np.integer)):
        if not 0 <= int(channel) <= 2:
            raise InputError(f"channel must be r, g, b or 0..2 (got {channel})")
        return int(channel)
    key = str(channel).strip().lower()
    if key.isdigit():
        return _channel_index(int(key))
    if key not in _CHANNELS:
        raise InputError(f"channel must be r, g, b (red, green, blue) or 0..2 (got {channel!r})")
    return _CHANNELS[key]


def scalar_channel(volume: Volume, channel=None) -> np.ndarray:
    """The image to threshold, ``(nx, ny, nz) float32``.

    A scalar volume is returned as is (``channel`` must be None); an RGB
    volume needs ``channel`` ('r', 'g', 'b', 'red', ..., or 0..2).
    """
    data = np.asarray(volume.data)
    if data.ndim == 3:
        if channel is not None:
            raise InputError(f"channel {channel!r} given but the volume is scalar (no colour channels)")
        return data.astype(np.float32, copy=False)
    if channel is None:
        raise InputError("the volume is RGB: choose a channel (e.g. channel='b', the paper's blue-background rule)")
    return np.ascontiguousarray(data[..., _channel_index(channel)], dtype=np.float32)


def smooth_mm(image: np.ndarray, spacing, sigma_mm: float) -> np.ndarray:
    """Gaussian-smooth ``image`` (nx, ny, nz) with sigma in mm (per axis sigma_mm / spacing)."""
    from scipy import ndimage

    if sigma_mm is None or sigma_mm <= 0:
        return image
    sigma = float(sigma_mm) / np.asarray(spacing, float)
    return ndimage.gaussian_filter(image.astype(np.float32, copy=False), sigma=sigma, mode="nearest")


def resample_isotropic(volume: Volume, voxel_size_mm: float, order: int) -> Volume:
    """Resample onto cubic voxels of ``voxel_size_mm`` covering the same world box.

    Voxel (0, 0, 0) keeps its centre (the origin is unchanged); the new grid
    has ``floor((n - 1) * spacing / voxel_size) + 1`` samples per axis so it
    never extrapolates.  ``order`` 0 (labels) or 1 (scalars, trilinear).
    """
    from scipy import ndimage

    v = float(voxel_size_mm)
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"voxel size must be a positive number of mm (got {voxel_size_mm})")
    data = np.asarray(volume.data)
    n = np.array(volume.shape)
    new_n = np.floor((n - 1) * volume.spacing / v + 1e-9).astype(int) + 1
    scale = v / volume.spacing  # new index -> old index
    out = ndimage.affine_transform(data, scale, output_shape=tuple(new_n), order=order, mode="nearest",
                                   prefilter=False)
    return Volume(out, np.full(3, v), volume.origin.copy(), volume.direction.copy())


def otsu_threshold(image: np.ndarray) -> float:
    """Otsu's threshold of the finite values of ``image``."""
    from skimage.filters import threshold_otsu

    values = image[np.isfinite(image)]
    if values.size == 0 or values.min() == values.max():
        raise EmptySegmentationError("Otsu threshold undefined: the image is constant")
    return float(threshold_otsu(values))


def threshold_mask(image: np.ndarray, low=None, high=None) -> np.ndarray:
    """``low <= image <= high`` (either bound may be None), ``(nx, ny, nz) bool``."""
    mask = np.isfinite(image)
    if low is not None:
        mask &= image >= low
    if high is not None:
        mask &= image <= high
    return mask


def _fmt(v) -> str:
    return "" if v is None else f"{v:g}"


def _ball(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None, None] ** 2 + r[None, :, None] ** 2 + r[None, None, :] ** 2) <= radius * radius


def clean_mask(mask: np.ndarray, radius: int = CLEAN_BALL_RADIUS_VOXELS) -> np.ndarray:
    """Binary opening (drops specks, thin spurs) then closing (closes pinholes)."""
    from scipy import ndimage

    ball = _ball(radius)
    out = ndimage.binary_opening(mask, structure=ball)
    # Pad before closing so objects touching the border are not eroded by it.
    pad = radius + 1
    closed = ndimage.binary_closing(np.pad(out, pad), structure=ball)
    return closed[pad:-pad, pad:-pad, pad:-pad]


def largest_connected_component(mask: np.ndarray) -> np.ndarray:
    """The largest 6-connected component of ``mask`` (an empty mask stays empty)."""
    from scipy import ndimage

    lab, n = ndimage.label(mask)
    if n <= 1:
        return mask.copy()
    counts = np.bincount(lab.ravel())
    counts[0] = 0
    return lab == int(np.argmax(counts))


def fill_mask_holes(mask: np.ndarray) -> np.ndarray:
    """Fill cavities not connected to the volume's border."""
    from scipy import ndimage

    return ndimage.binary_fill_holes(mask)


#: An integer volume with at most this many values (all in 0..255) and no rule given is a label map.
MAX_AUTO_LABELS = 32


def looks_like_labels(volume: Volume) -> bool:
    """True for a 3D integer volume with at most :data:`MAX_AUTO_LABELS` values, all in 0..255.

    Such a volume given without a segmentation rule is taken as a label map
    (``cutkit segment`` and ``cutkit build-model``).
    """
    data = np.asarray(volume.data)
    if data.ndim != 3 or not np.issubdtype(data.dtype, np.integer):
        return False
    values = np.unique(data)
    return len(values) <= MAX_AUTO_LABELS and values[0] >= 0 and values[-1] <= 255


def check_sizes(smooth_sigma_mm=None, voxel_size_mm=None, names=("smoothing sigma", "voxel size")) -> None:
    """Raise :class:`InputError` for a negative or non-finite sigma or a voxel size that is not positive.

    ``names`` are the words the message uses for the two (the command line passes its flags).
    """
    if smooth_sigma_mm is not None and not (np.isfinite(smooth_sigma_mm) and smooth_sigma_mm >= 0):
        raise InputError(f"{names[0]} must be a number of mm >= 0 (0: no smoothing), got {smooth_sigma_mm:g}")
    if voxel_size_mm is not None and not (np.isfinite(voxel_size_mm) and voxel_size_mm > 0):
        raise InputError(f"{names[1]} must be a positive number of mm, got {voxel_size_mm:g}")


def _labels_volume(volume: Volume, labels) -> Volume:
    if labels is True:
        labels = volume
    if isinstance(labels, Volume):
        lv = labels
    else:
        arr = np.asarray(labels)
        if arr.shape != volume.shape:
            raise InputError(f"label map shape {arr.shape} differs from the volume's {volume.shape}")
        lv = Volume(arr, volume.spacing, volume.origin, volume.direction)
    data = np.asarray(lv.data)
    if data.ndim != 3 or not np.issubdtype(data.dtype, np.integer):
        raise InputError(f"a label map must be a 3D integer volume (got {data.dtype} of shape {data.shape})")
    if data.min() < 0 or data.max() > 255:
        raise InputError(f"labels must lie in 0..255 for a uint8 label map (got {data.min()}..{data.max()})")
    return Volume(data.astype(np.uint8), lv.spacing, lv.origin, lv.direction)


def _smooth_labels(lv: Volume, sigma_mm: float) -> np.ndarray:
    """Smooth every label's indicator and keep, per voxel, the strongest one."""
    data = lv.data
    values = np.unique(data)
    best = np.zeros(data.shape, np.float32)
    out = np.zeros_like(data)
    for v in values:
        s = smooth_mm((data == v).astype(np.float32), lv.spacing, sigma_mm)
        take = s > best
        out[take] = v
        best[take] = s[take]
    return out


def segment(
    volume: Volume,
    threshold=None,
    channel=None,
    otsu: bool = False,
    labels=None,
    smooth_sigma_mm: float | None = None,
    voxel_size_mm: float | None = None,
    clean: bool = False,
    largest_component: bool = True,
    fill_holes: bool = True,
    report: dict | None = None,
) -> Volume:
    """Segment ``volume`` into a uint8 label map.

    Parameters
    ----------
    volume : Volume
        Scalar ``(nx, ny, nz)`` or RGB ``(nx, ny, nz, 3)`` volume.
    threshold : (low, high), optional
        Keep ``low <= value <= high``; either bound may be None.
    channel : {'r', 'g', 'b', 'red', 'green', 'blue', 0, 1, 2}, optional
        Colour channel of RGB data (required for RGB).
    otsu : bool
        Threshold at Otsu's value (bright side kept; dark side for the blue
        channel).  Used also when neither ``threshold`` nor ``labels`` is given.
    labels : Volume, (nx, ny, nz) int array or True, optional
        A label map used as is (True: ``volume`` itself is one).
    smooth_sigma_mm : float, optional
        Gaussian sigma in mm applied before thresholding (label maps: per label).
    voxel_size_mm : float, optional
        Resample to cubic voxels of this size (order 1 for images, 0 for labels).
    clean, largest_component, fill_holes : bool
        Opening+closing with a ball of ``CLEAN_BALL_RADIUS_VOXELS`` (off by
        default: the opening erases structures thinner than three voxels,
        e.g. white matter at 2 mm); keep the largest connected component;
        fill enclosed cavities.  For label maps only ``largest_component``
        applies (to the non-zero voxels).
    report : dict, optional
        Filled with what the clean-up changed: ``voxels_selected`` (before
        it), ``voxels_kept`` (after it), ``cleanup_change_percent``
        (kept / selected - 1, in per cent) and ``voxel_mm3``.

    Returns
    -------
    Volume
        uint8 ``(nx', ny', nz')``: 1 = foreground of a thresholded image, or
        the given labels; geometry updated by the resampling.

    Raises
    ------
    EmptySegmentationError
        No voxel selected.
    InputError
        A negative smoothing sigma or a voxel size that is not positive.
    """
    check_sizes(smooth_sigma_mm, voxel_size_mm)
    if labels is not None and labels is not False:
        lv = _labels_volume(volume, labels)
        if smooth_sigma_mm:
            lv = Volume(_smooth_labels(lv, smooth_sigma_mm), lv.spacing, lv.origin, lv.direction)
        if voxel_size_mm is not None:
            lv = resample_isotropic(lv, voxel_size_mm, order=0)
        data = lv.data
        selected = int(np.count_nonzero(data))
        if largest_component and np.any(data):
            data = np.where(largest_connected_component(data > 0), data, 0).astype(np.uint8)
        _cleanup_report(report, selected, int(np.count_nonzero(data)), lv.spacing)
        if not np.any(data):
            raise EmptySegmentationError("label map selects no voxel (all labels are 0)")
        return Volume(np.ascontiguousarray(data, np.uint8), lv.spacing, lv.origin, lv.direction)

    if np.asarray(volume.data).ndim == 4 and channel is None:
        raise InputError("the volume is RGB: choose a channel (e.g. --channel blue, the paper's blue-background rule)")
    image = smooth_mm(scalar_channel(volume, channel), volume.spacing, smooth_sigma_mm)
    grid = Volume(image, volume.spacing, volume.origin, volume.direction)
    if voxel_size_mm is not None:
        grid = resample_isotropic(grid, voxel_size_mm, order=1)
    image = grid.data
    dark_side = channel is not None and _channel_index(channel) == 2
    if threshold is not None and not otsu:
        low, high = threshold
        rule = f"threshold {_fmt(low)}:{_fmt(high)}"
    else:
        t = otsu_threshold(image)
        low, high = (None, t) if dark_side else (t, None)
        rule = f"Otsu threshold {t:.4g} ({'below' if dark_side else 'above'})"
    mask = threshold_mask(image, low, high)
    if not mask.any():
        finite = image[np.isfinite(image)]
        raise EmptySegmentationError(
            f"segmentation selects no voxel ({rule}; values range {finite.min():.4g}..{finite.max():.4g})"
        )
    selected = int(np.count_nonzero(mask))
    if clean:
        mask = clean_mask(mask)
    if largest_component:
        mask = largest_connected_component(mask)
    if fill_holes:
        mask = fill_mask_holes(mask)
    _cleanup_report(report, selected, int(np.count_nonzero(mask)), grid.spacing)
    if not mask.any():
        raise EmptySegmentationError(f"segmentation is empty after clean-up ({rule}); try --no-clean")
    return Volume(mask.astype(np.uint8), grid.spacing, grid.origin, grid.direction)


#: A clean-up that changes the segmented volume by more than this many per cent is worth a warning.
CLEANUP_WARN_PERCENT = 3.0


def _cleanup_report(report, selected: int, kept: int, spacing) -> None:
    if report is None:
        return
    report.update(voxels_selected=selected, voxels_kept=kept, voxel_mm3=float(np.prod(spacing)),
                  cleanup_change_percent=100.0 * (kept - selected) / selected if selected else 0.0)


def cleanup_warning(report: dict) -> str | None:
    """A one-line warning when the clean-up of :func:`segment` changed the volume by more than
    :data:`CLEANUP_WARN_PERCENT`, else None."""
    change = report.get("cleanup_change_percent")
    if change is None or abs(change) <= CLEANUP_WARN_PERCENT:
        return None
    mm3 = report["voxel_mm3"] * (report["voxels_kept"] - report["voxels_selected"])
    return (f"the clean-up changed the segmented volume by {change:+.1f} % ({mm3:+.0f} mm^3); "
            "thin structures or islands were lost: try --no-clean (or a smaller voxel size)")
