"""Register a 3D texture volume to a model and give every node texture coordinates.

Paper section 7.2: every node starts with the canonical texture coordinate
of its position in the data set, but "filtering and isosurface mesh
construction generate positional drifts of the nodes", so the texture is
registered explicitly once, in preprocessing.  Here the mesh boundary is
fitted to the isosurface of the original segmentation by iterative closest
points (ICP, rigid or affine); the fitted transform maps every node into the
texture volume.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cutkit.errors import InputError
from cutkit.model.tetmodel import TetModel, Texture
from cutkit.volumes.volume import Volume

#: ICP stops when the RMS residual improves by less than this (mm) ...
ICP_TOLERANCE_MM = 1e-4
#: ... or after this many iterations.
ICP_MAX_ITERATIONS = 40
#: Texture volumes larger than this many voxels are block-averaged down.
DEFAULT_MAX_VOXELS = 8_000_000


@dataclass
class TextureReport:
    """What registration did: residuals in mm (RMS of boundary-node distance to the isosurface)."""

    method: str
    residual_before_mm: float
    residual_after_mm: float
    iterations: int
    transform: np.ndarray  # (4, 4) float64, mesh world -> texture world
    texture_shape: tuple
    downsample_factor: int


def downsample_texture(volume: Volume, max_voxels: int = DEFAULT_MAX_VOXELS) -> tuple[Volume, int]:
    """Block-average ``volume`` by the smallest integer factor that fits ``max_voxels``.

    Returns the (possibly unchanged) volume and the factor.  The origin moves to
    the centre of the first block so world positions of voxel centres stay right.
    """
    n = int(np.prod(volume.shape))
    factor = 1
    while n / factor**3 > max_voxels:
        factor += 1
    if factor == 1:
        return volume, 1
    data = volume.data if volume.data.ndim == 4 else volume.data[..., None]
    sx, sy, sz = (s // factor * factor for s in data.shape[:3])
    d = data[:sx, :sy, :sz].astype(np.float32)
    d = d.reshape(sx // factor, factor, sy // factor, factor, sz // factor, factor, d.shape[3]).mean(axis=(1, 3, 5))
    spacing = volume.spacing * factor
    origin = volume.origin + volume.direction @ (volume.spacing * (factor - 1) / 2.0)
    out = np.clip(np.rint(d), 0, 255).astype(np.uint8)
    return Volume(out, spacing=spacing, origin=origin, direction=volume.direction), factor


def pad_background(texture: Volume, segmentation: Volume) -> Volume:
    """Give every background voxel of ``texture`` the colour of the nearest tissue voxel.

    Trilinear sampling at a boundary node mixes the tissue's colour with the
    background's (the blue gel of a cryosection, paper section 7.2), which
    tints the whole model surface.  Bleeding the tissue colours outwards
    keeps every sample at or inside the boundary a tissue colour.

    Parameters
    ----------
    texture : Volume
        ``data`` (nx, ny, nz) or (nx, ny, nz, c).
    segmentation : Volume
        Label map in the same world frame (label > 0 is tissue), any grid.

    Returns
    -------
    Volume
        The texture with background voxels replaced (unchanged if the
        segmentation covers none of the texture's voxels).
    """
    from scipy import ndimage

    shape = texture.data.shape[:3]
    centres = texture.index_to_world(np.indices(shape).reshape(3, -1).T)
    ijk = np.rint(segmentation.world_to_index(centres)).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < np.array(segmentation.data.shape[:3])), axis=1)
    tissue = np.zeros(ijk.shape[0], bool)
    s = ijk[inside]
    tissue[inside] = np.asarray(segmentation.data)[s[:, 0], s[:, 1], s[:, 2]] > 0
    tissue = tissue.reshape(shape)
    # texture voxels at the boundary mix tissue and background; where the
    # segmentation is coarser than the texture its boundary is off by up to a
    # segmentation voxel: keep only texture voxels that far inside
    steps = int(np.ceil(np.max(segmentation.spacing) / np.min(texture.spacing) - 1e-9))
    core = ndimage.binary_erosion(tissue, iterations=steps) if steps > 1 else tissue
    if core.any():
        tissue = core
    if not tissue.any() or tissue.all():
        return texture
    _, idx = ndimage.distance_transform_edt(~tissue, return_indices=True)
    data = texture.data[idx[0], idx[1], idx[2]]
    return Volume(data, spacing=texture.spacing, origin=texture.origin, direction=texture.direction)


def _as_texture(volume: Volume) -> Texture:
    data = volume.data
    if data.ndim == 3:
        data = data[..., None]
    if data.shape[3] not in (1, 3):
        raise InputError(f"texture volume has {data.shape[3]} channels; expected grey (1) or RGB (3)")
    if data.dtype != np.uint8:
        lo, hi = float(np.nanmin(data)), float(np.nanmax(data))
        scale = 255.0 / (hi - lo) if hi > lo else 0.0
        data = np.clip(np.rint((data.astype(np.float64) - lo) * scale), 0, 255).astype(np.uint8)
    return Texture(volume=np.ascontiguousarray(data), spacing=volume.spacing, origin=volume.origin, direction=volume.direction)


def fit_transform(source: np.ndarray, target: np.ndarray, method: str) -> np.ndarray:
    """Least-squares transform taking ``source`` points onto ``target`` points.

    Parameters
    ----------
    source, target : (k, 3) float64
        Corresponding points.
    method : {'rigid', 'affine'}

    Returns
    -------
    transform : (4, 4) float64
    """
    t = np.eye(4)
    if method == "affine":
        a = np.hstack([source, np.ones((source.shape[0], 1))])
        sol, *_ = np.linalg.lstsq(a, target, rcond=None)
        t[:3, :3] = sol[:3].T
        t[:3, 3] = sol[3]
        return t
    # Kabsch: rotation from the SVD of the cross-covariance, reflection removed.
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    h = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    t[:3, :3] = r
    t[:3, 3] = ct - r @ cs
    return t


def _apply(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ transform[:3, :3].T + transform[:3, 3]


def _isosurface_points(segmentation: Volume) -> np.ndarray:
    from skimage.measure import marching_cubes

    mask = (np.asarray(segmentation.data) > 0).astype(np.float32)
    if mask.ndim != 3 or not mask.any():
        raise InputError("segmentation for texture registration is empty or not a 3D label map")
    padded = np.pad(mask, 1)
    verts, *_ = marching_cubes(padded, level=0.5)
    return segmentation.index_to_world(verts - 1.0)


def register_texture(
    model: TetModel,
    texture_volume: Volume,
    segmentation: Volume | None = None,
    method: str = "rigid",
    max_voxels: int = DEFAULT_MAX_VOXELS,
) -> tuple[TetModel, TextureReport]:
    """Attach a texture to ``model`` and give each node texture coordinates.

    Parameters
    ----------
    model : TetModel
    texture_volume : Volume
        Grey or RGB volume in the same world frame as the segmentation.
    segmentation : Volume, optional
        Label map the mesh was built from; its isosurface (label > 0) is the
        registration target.  Required unless ``method == 'none'``.
    method : {'none', 'rigid', 'affine'}
    max_voxels : int
        Texture volumes above this size are block-averaged down.

    Returns
    -------
    model : TetModel
        With ``texture`` and ``texcoords`` set.
    report : TextureReport
    """
    from scipy.spatial import cKDTree

    from cutkit.mesh.topology import boundary_faces

    if method not in ("none", "rigid", "affine"):
        raise InputError(f"texture registration method must be none, rigid or affine, not {method!r}")
    tex_volume, factor = downsample_texture(texture_volume, max_voxels)
    if segmentation is not None:
        tex_volume = pad_background(tex_volume, segmentation)
    texture = _as_texture(tex_volume)

    transform = np.eye(4)
    before = after = float("nan")
    iterations = 0
    if segmentation is not None:
        surface = _isosurface_points(segmentation)
        tree = cKDTree(surface)
        faces, _ = boundary_faces(model.tets)
        nodes = model.points[np.unique(faces)]
        dist, idx = tree.query(nodes)
        before = after = float(np.sqrt(np.mean(dist**2)))
        if method != "none":
            for iterations in range(1, ICP_MAX_ITERATIONS + 1):
                moved = _apply(transform, nodes)
                dist, idx = tree.query(moved)
                rms = float(np.sqrt(np.mean(dist**2)))
                if iterations > 1 and after - rms < ICP_TOLERANCE_MM:
                    after = min(after, rms)
                    break
                after = rms
                step = fit_transform(moved, surface[idx], method)
                transform = step @ transform
            dist, _ = tree.query(_apply(transform, nodes))
            after = float(np.sqrt(np.mean(dist**2)))
    elif method != "none":
        raise InputError(f"texture registration '{method}' needs the segmentation the mesh was built from")

    texcoords = texture.index_to_texcoord(texture.world_to_index(_apply(transform, model.points)))
    provenance = dict(model.provenance)
    stages = dict(provenance.get("stages", {}))
    stages["texture"] = {
        "method": method,
        "residual_before_mm": before,
        "residual_after_mm": after,
        "transform": transform.tolist(),
        "downsample_factor": factor,
    }
    provenance["stages"] = stages
    out = dataclasses.replace(model, texture=texture, texcoords=texcoords, provenance=provenance)
    report = TextureReport(method, before, after, iterations, transform, texture.volume.shape, factor)
    return out, report
