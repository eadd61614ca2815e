"""Segmentation of volumes into uint8 label maps (paper section 7.1, first step)."""

from cutkit.segment.segment import (
    CLEAN_BALL_RADIUS_VOXELS,
    CLEANUP_WARN_PERCENT,
    check_sizes,
    clean_mask,
    cleanup_warning,
    fill_mask_holes,
    largest_connected_component,
    looks_like_labels,
    otsu_threshold,
    resample_isotropic,
    scalar_channel,
    segment,
    smooth_mm,
    threshold_mask,
)

__all__ = [
    "segment",
    "scalar_channel",
    "smooth_mm",
    "resample_isotropic",
    "threshold_mask",
    "otsu_threshold",
    "clean_mask",
    "largest_connected_component",
    "fill_mask_holes",
    "CLEAN_BALL_RADIUS_VOXELS",
    "CLEANUP_WARN_PERCENT",
    "check_sizes",
    "cleanup_warning",
    "looks_like_labels",
]
