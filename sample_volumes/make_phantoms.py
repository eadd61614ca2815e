"""Generate the sample volumes of cutkit (deterministic: fixed seeds).

Run from the repository root::

    .venv/bin/python sample_volumes/make_phantoms.py            # all files
    .venv/bin/python sample_volumes/make_phantoms.py --only block

World coordinates are LPS mm (x to the left, y posterior, z superior); the
front of the knee faces -y.  The knee is defined analytically
(:func:`knee_label_at`) and sampled on each grid, so the label map, the
colour volume and the CT-like volume agree at any resolution.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: Label values of the knee phantom.
LABELS = {0: "background", 1: "skin", 2: "fat", 3: "muscle", 4: "tendon", 5: "bone"}

#: The knee's box in world mm: x, y in [-0.5, 80.5], z in [0, 120] (whole 1 and 1.5 mm voxels).
BOX_MIN = np.array([-0.5, -0.5, 0.0])
BOX_SIZE = np.array([81.0, 81.0, 120.0])

#: The leg's axis runs along z through (x, y) = CENTRE; its front skin lies near y = 5 mm.
CENTRE = np.array([40.0, 40.0])
JOINT_Z = 60.0  # the tibial plateau meets the femoral condyles here
SKIN_MM = 2.5
FAT_MM = 5.0

#: RGB of each tissue (cryosection-like); background is the blue gel.
COLOURS = {
    0: (25, 50, 230),
    1: (210, 140, 105),
    2: (225, 195, 80),
    3: (130, 40, 40),
    4: (190, 185, 120),
    5: (225, 210, 110),
}

#: Hounsfield-like values of the CT-like volume.
CT_VALUES = {0: -1000, 1: 20, 2: -100, 3: 40, 4: 90, 5: 700}


def grid(spacing: float):
    """Voxel-centre coordinates (x, y, z) 1D arrays and the origin of a grid over the box."""
    n = np.round(BOX_SIZE / spacing).astype(int)
    axes = [BOX_MIN[a] + spacing * (0.5 + np.arange(n[a])) for a in range(3)]
    origin = np.array([ax[0] for ax in axes])
    return axes, origin


def _leg_radius(z):
    """Half-axes (rx, ry) of the leg's elliptic section: widest at the joint."""
    bulge = 2.0 * np.exp(-(((z - JOINT_Z) / 25.0) ** 2))
    return 34.0 + bulge, 33.0 + bulge


def knee_label_at(x, y, z) -> np.ndarray:
    """Tissue label (uint8) at world points (broadcastable arrays, mm)."""
    x, y, z = np.broadcast_arrays(x, y, z)
    x = x - CENTRE[0]  # leg-centred coordinates from here on
    y = y - CENTRE[1]
    rx, ry = _leg_radius(z)
    r = np.sqrt((x / rx) ** 2 + (y / ry) ** 2)  # 1 on the skin surface
    depth = (1.0 - r) * np.minimum(rx, ry)  # approximate depth below the skin, mm
    lab = np.zeros(x.shape, np.uint8)
    lab[depth >= 0] = 1
    lab[depth >= SKIN_MM] = 2
    lab[depth >= SKIN_MM + FAT_MM] = 3
    # Patellar tendon: a strip in front (-y) from the tibial tuberosity to the patella.
    tendon = (np.abs(x) <= 7.0) & (y >= -28.0) & (y <= -20.0) & (z >= 38.0) & (z <= 72.0)
    lab[tendon] = 4
    # Femur: a shaft above the joint ending in two condyle bulges.
    femur = (x ** 2 + y ** 2 <= 11.0 ** 2) & (z >= JOINT_Z + 10.0)
    for cx in (-11.0, 11.0):
        femur |= ((x - cx) ** 2 + (y - 2.0) ** 2) / 12.0 ** 2 + ((z - (JOINT_Z + 10.0)) / 10.0) ** 2 <= 1.0
    femur &= z >= JOINT_Z
    # Tibia: a shaft below the joint widening into the plateau.
    plateau = 11.0 + 11.0 * np.clip((z - (JOINT_Z - 20.0)) / 20.0, 0.0, 1.0)
    tibia = (x ** 2 / plateau ** 2 + (y - 2.0) ** 2 / (0.75 * plateau) ** 2 <= 1.0) & (z < JOINT_Z - 1.0)
    # Patella: a flat ellipsoid in front of the femur, above the tendon.
    patella = (x / 10.0) ** 2 + ((y + 21.0) / 4.5) ** 2 + ((z - 80.0) / 11.0) ** 2 <= 1.0
    lab[femur | tibia | patella] = 5
    return lab


def knee_labels(spacing: float = 1.5):
    """The knee label map on a grid of ``spacing`` mm: (labels uint8, origin, spacing)."""
    (xs, ys, zs), origin = grid(spacing)
    lab = knee_label_at(xs[:, None, None], ys[None, :, None], zs[None, None, :])
    return lab, origin, np.full(3, spacing)


def knee_rgb(spacing: float = 1.0, seed: int = 7):
    """Cryosection-like colours: uint8 (nx, ny, nz, 3), origin, spacing.

    Muscle gets a fibre striation constant along z (fibres run along the
    leg): a smoothed random pattern in (x, y) repeated over z.
    """
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    lab, origin, sp = knee_labels(spacing)
    palette = np.array([COLOURS[k] for k in sorted(COLOURS)], np.float32)
    rgb = palette[lab]
    nx, ny, nz = lab.shape
    fibres = ndimage.gaussian_filter(rng.standard_normal((nx, ny)).astype(np.float32), 0.8)
    fibres /= fibres.std()
    drift = ndimage.gaussian_filter1d(rng.standard_normal(nz).astype(np.float32), 6.0)
    striation = fibres[:, :, None] * (1.0 + 0.3 * drift[None, None, :])
    muscle = lab == 3
    rgb[muscle] += (18.0 * striation[muscle])[:, None] * np.array([1.0, 0.35, 0.3], np.float32)
    rgb += rng.normal(0.0, 5.0, rgb.shape).astype(np.float32)
    return np.clip(np.round(rgb), 0, 255).astype(np.uint8), origin, sp


def knee_ct(spacing: float = 1.5, seed: int = 11):
    """CT-like int16 volume (Hounsfield-like units) of the knee, slightly blurred, with noise."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    lab, origin, sp = knee_labels(spacing)
    lut = np.array([CT_VALUES[k] for k in sorted(CT_VALUES)], np.float32)
    ct = ndimage.gaussian_filter(lut[lab], 0.7)
    ct += rng.normal(0.0, 15.0, ct.shape).astype(np.float32)
    return np.round(ct).astype(np.int16), origin, sp


def block_labels():
    """Small two-label block for tests: (20, 12, 10) uint8, origin, spacing.

    Background margin of one voxel; label 1 for i in 1..9 and label 2 for
    i in 10..18, both for j in 1..10 and k in 1..8.  Spacing 2 x 1.5 x 1 mm,
    origin (-10, 5, 20) mm.
    """
    lab = np.zeros((20, 12, 10), np.uint8)
    lab[1:10, 1:11, 1:9] = 1
    lab[10:19, 1:11, 1:9] = 2
    return lab, np.array([-10.0, 5.0, 20.0]), np.array([2.0, 1.5, 1.0])


def _write(name: str, data, origin, spacing) -> None:
    from cutkit.volumes import Volume, write_volume

    path = HERE / name
    write_volume(path, Volume(data, spacing, origin))
    sp = [float(s) for s in spacing]
    print(f"{path.name}: {data.shape} {data.dtype}, spacing {sp} mm, {path.stat().st_size / 1e6:.2f} MB")


MAKERS = {
    "block": lambda: _write("block_labels.nrrd", *block_labels()),
    "labels": lambda: _write("knee_labels.nrrd", *knee_labels()),
    "rgb": lambda: _write("knee_rgb.nrrd", *knee_rgb()),
    "ct": lambda: _write("knee_ct.nrrd", *knee_ct()),
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=sorted(MAKERS), action="append", help="make only this file (repeatable)")
    args = ap.parse_args(argv)
    for name in args.only or MAKERS:
        MAKERS[name]()


if __name__ == "__main__":
    main()
