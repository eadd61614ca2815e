"""``build-model``: the preprocessing chain of the paper's section 7, stage by stage.

The stages are listed once, in :data:`STAGES`, in the order they run:
segment -> isovolume -> decimate -> assign -> texture.  Each takes the
:class:`BuildContext` and records what it did; each is also its own
command (``cutkit segment``, ``cutkit isovolume``, ...), so a user can stop
after any stage, look at the result in ParaView and go on.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from cutkit import __version__
from cutkit.errors import InputError
from cutkit.model.tetmodel import TetModel
from cutkit.volumes.volume import Volume


@dataclass
class BuildContext:
    """What flows between the stages."""

    recipe: dict
    volume: Volume | None = None
    volume_path: str | None = None
    segmentation: Volume | None = None
    #: a label map given with the volume (``--labels``), segmented as it is
    labels: Volume | None = None
    model: TetModel | None = None
    #: stage name -> {"seconds": float, ...figures the stage reports}
    report: dict = field(default_factory=dict)


def _stage_segment(ctx: BuildContext) -> dict:
    from cutkit.segment import segment

    from cutkit.segment import looks_like_labels

    opts = ctx.recipe.get("segment", {})
    vol = ctx.volume
    cleanup: dict = {}
    rule = opts.get("labels") or "threshold" in opts or opts.get("otsu") or opts.get("channel")
    if ctx.labels is None and not rule:
        if not looks_like_labels(vol):
            raise InputError(f"{ctx.volume_path}: no segmentation rule and the volume is not a label map: "
                             "give --threshold, --otsu, --channel, --labels or a recipe [segment] table")
        opts = {**opts, "labels": True}  # an integer volume of a few values in 0..255 is a label map
    if ctx.labels is not None or opts.get("labels", False):
        # a given label map is used as it is: only smoothing and resampling apply
        lv = ctx.labels if ctx.labels is not None else vol
        seg = segment(vol, labels=lv, smooth_sigma_mm=opts.get("smooth_mm"),
                      voxel_size_mm=opts.get("voxel_size_mm"),
                      largest_component=opts.get("largest_component", ctx.labels is None), report=cleanup)
    else:
        threshold = opts.get("threshold")
        if threshold is not None:
            threshold = (float(threshold[0]), float(threshold[1]) if len(threshold) > 1 else None)
        seg = segment(
            vol,
            threshold=threshold,
            channel=opts.get("channel"),
            otsu=bool(opts.get("otsu", False)),
            smooth_sigma_mm=opts.get("smooth_mm") or None,
            voxel_size_mm=opts.get("voxel_size_mm"),
            clean=opts.get("clean", False),
            largest_component=opts.get("largest_component", True),
            fill_holes=opts.get("fill_holes", True),
            report=cleanup,
        )
    ctx.segmentation = seg
    voxel_mm3 = float(np.prod(seg.spacing))
    labels, counts = np.unique(seg.data[seg.data > 0], return_counts=True)
    return {"labels": {int(l): float(c) * voxel_mm3 for l, c in zip(labels, counts)}, "shape": list(seg.shape),
            **cleanup}


def _stage_isovolume(ctx: BuildContext) -> dict:
    from cutkit.isovolume import isovolume

    opts = ctx.recipe.get("isovolume", {})
    kwargs = {}
    if "snap" in opts:
        kwargs["snap"] = float(opts["snap"])
    ctx.model = isovolume(ctx.segmentation, level=float(opts.get("level", 0.5)), **kwargs)
    return {"tets": ctx.model.n_tets, "nodes": ctx.model.n_points}


def _stage_decimate(ctx: BuildContext) -> dict:
    opts = ctx.recipe.get("decimate")
    if not opts:
        return {"skipped": True}
    from cutkit.decimate import decimate

    before = ctx.model.n_tets
    ctx.model = decimate(
        ctx.model,
        target_tets=opts.get("target_tets"),
        ratio=opts.get("ratio"),
        surface_tolerance_mm=opts.get("surface_tolerance_mm"),
        min_dihedral_deg=float(opts.get("min_dihedral_deg", 10.0)),
    )
    out = {"tets_before": before, "tets": ctx.model.n_tets, "nodes": ctx.model.n_points}
    if opts.get("optimize"):
        from cutkit.decimate.optimize import optimize

        ctx.model, out["optimize"] = optimize(ctx.model, opts["optimize"])
        out.update(tets=ctx.model.n_tets, nodes=ctx.model.n_points)
    return out


def _stage_assign(ctx: BuildContext) -> dict:
    from cutkit.assign import assign

    warnings: list[str] = []
    ctx.model = assign(ctx.model, ctx.recipe, warnings=warnings)
    b = ctx.model.boundary
    return {
        "warnings": warnings,
        "materials": len(ctx.model.materials.name),
        "fixed_nodes": int(b.fixed_nodes.size),
        "prescribed_nodes": int(b.prescribed_nodes.size),
        "prestressed_labels": int(ctx.model.prestress.label.size),
    }


def _stage_texture(ctx: BuildContext) -> dict:
    opts = ctx.recipe.get("texture")
    if not opts:
        return {"skipped": True}
    from cutkit.texture import register_texture
    from cutkit.volumes import read_volume

    tex_path = opts.get("volume")
    tex_volume = read_volume(tex_path) if tex_path else ctx.volume
    kwargs = {}
    if "max_voxels" in opts:
        kwargs["max_voxels"] = int(opts["max_voxels"])
    ctx.model, rep = register_texture(
        ctx.model, tex_volume, segmentation=ctx.segmentation, method=opts.get("register", "rigid"), **kwargs
    )
    if tex_path:
        ctx.model.provenance.setdefault("inputs", {})[str(tex_path)] = file_sha256(tex_path)
    return {"residual_before_mm": rep.residual_before_mm, "residual_after_mm": rep.residual_after_mm,
            "iterations": rep.iterations}


#: The build chain, in order: (stage name, function).
STAGES: list[tuple[str, Callable[[BuildContext], dict]]] = [
    ("segment", _stage_segment),
    ("isovolume", _stage_isovolume),
    ("decimate", _stage_decimate),
    ("assign", _stage_assign),
    ("texture", _stage_texture),
]


def file_sha256(path: str | Path) -> str:
    """``sha256:<hex>`` of a file (what ``sha256sum`` prints), or of a folder's files.

    A folder (a DICOM series) hashes each file's name and content, in name order.
    """
    path = Path(path)
    h = hashlib.sha256()
    folder = path.is_dir()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if folder else [path]
    for p in files:
        if folder:
            h.update(p.name.encode())
        with open(p, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return "sha256:" + h.hexdigest()


def run_build(
    volume_path: str | Path,
    recipe: dict,
    on_stage: Callable[[str, str], None] | None = None,
    spacing=None,
    labels_path: str | Path | None = None,
    keep_record: bool = False,
) -> BuildContext:
    """Run every stage of :data:`STAGES` on a volume.

    Parameters
    ----------
    volume_path : path-like
        Input volume (any format :func:`cutkit.volumes.read_volume` reads).
    recipe : dict
        Validated recipe (command-line overrides already merged in).
    on_stage : callable(name, event), optional
        Called with event ``"start"`` and ``"done"`` around each stage (for progress display).
    spacing : (3,) float, optional
        Voxel spacing for formats that carry none (.npy).
    keep_record : bool
        Keep the decimation's progressive record (``extra/progressive``: the
        finest mesh and every collapse, so ``cutkit decimate --level`` can
        extract other levels).  Off by default: it holds the isovolume's
        millions of tets and would make the model ten times larger than its
        own mesh (docs/model-format.md).
    labels_path : path-like, optional
        A label map used as the segmentation as it is (the recipe's smoothing
        and resampling still apply); the volume serves only as the default
        texture.

    Returns
    -------
    BuildContext
        ``ctx.model`` is the finished model (with provenance); ``ctx.report``
        holds each stage's figures and seconds.
    """
    from cutkit.volumes import read_volume

    volume_path = Path(volume_path)
    if not volume_path.exists():
        raise InputError(f"{volume_path}: no such file or folder")
    ctx = BuildContext(recipe=recipe, volume_path=str(volume_path))
    t0 = time.perf_counter()
    ctx.volume = read_volume(volume_path, spacing=spacing) if spacing is not None else read_volume(volume_path)
    ctx.report["read"] = {"seconds": time.perf_counter() - t0, "shape": list(ctx.volume.shape)}
    if labels_path is not None:
        ctx.labels = read_volume(labels_path)
        if not np.any(np.asarray(ctx.labels.data) > 0):
            from cutkit.errors import EmptySegmentationError

            raise EmptySegmentationError(f"{labels_path}: the label map has no voxel with a label > 0")
    for name, fn in STAGES:
        if on_stage:
            on_stage(name, "start")
        t0 = time.perf_counter()
        figures = fn(ctx)
        figures["seconds"] = time.perf_counter() - t0
        ctx.report[name] = figures
        if on_stage:
            on_stage(name, "done")

    if not keep_record:
        from cutkit.decimate.progressive import RECORD

        ctx.model.extra.pop(RECORD, None)
    prov = dict(ctx.model.provenance)
    prov["cutkit_version"] = __version__
    prov["recipe"] = {k: v for k, v in recipe.items() if not k.startswith("_")}
    prov["recipe_file"] = recipe.get("_path")
    prov["recipe_sha256"] = recipe.get("_sha256")
    prov.setdefault("inputs", {})[str(volume_path)] = file_sha256(volume_path)
    if labels_path is not None:
        prov["inputs"][str(labels_path)] = file_sha256(labels_path)
    prov["stage_figures"] = {k: {kk: vv for kk, vv in v.items()} for k, v in ctx.report.items()}
    ctx.model.provenance = prov
    return ctx
