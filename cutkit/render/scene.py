"""One picture of a frame: tissue, cut surface, blade path, scale bar, axes, legend, title."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.errors import InputError

#: Views ``camera_for`` knows: the wound from outside, and the whole tissue from
#: the front (-y, anterior in LPS), the patient's left side (+x), above (+z).
VIEWS = ("cut", "overview", "front", "side", "top")

#: Colours (RGB 0..1).
CUT_COLOUR = (0.80, 0.10, 0.12)
RIM_COLOUR = (0.35, 0.0, 0.0)
PATH_COLOUR = (0.10, 0.35, 0.85)
TISSUE_COLOUR = (0.87, 0.66, 0.58)
#: Height of the title band as a fraction of the picture.
TITLE_BAND = 0.08
#: Camera distance of the whole-tissue views over the bounding box's diagonal (30 degree view angle).
WHOLE = 1.7
#: The close-up ("cut" view) stands at least this many times the model's smallest bounding-box side
#: away: the view then spans about 0.6 (high) by 0.8 (wide) of that side, so a small model's outline
#: shows around a short cut and the model stays recognisable.
CLOSE_UP_MIN = 1.1


@dataclass
class Camera:
    """Where the camera is: ``focal`` point (mm), direction it looks along, ``up``, ``distance`` (mm)."""

    focal: np.ndarray
    view_dir: np.ndarray
    up: np.ndarray
    distance: float

    def position(self):
        d = np.asarray(self.view_dir, float)
        d = d / np.linalg.norm(d)
        f = np.asarray(self.focal, float)
        return [tuple(f - self.distance * d), tuple(f), tuple(np.asarray(self.up, float))]


def _unit(v):
    v = np.asarray(v, float)
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _perpendicular(v):
    v = _unit(v)
    a = np.array([0.0, 0.0, 1.0]) if abs(v[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    return _unit(np.cross(v, a))


def _read(path):
    import pyvista as pv

    try:
        return pv.read(str(path))
    except Exception as exc:  # VTK raises many kinds for damaged files
        raise InputError(f"{path}: cannot read ({' '.join(str(exc).split()) or type(exc).__name__})") from None


def camera_for(folder, view: str = "cut") -> Camera:
    """A camera that frames the run of ``folder`` (a :class:`~cutkit.render.Folder`) for ``view``.

    ``cut`` looks into the wound from outside: along the blade's way into the
    tissue, tilted a little across the cut plane so the cut surface shows; up
    is the cut plane's normal, so the incision runs across the picture.
    Without a cut it is ``overview``.  The other views frame the whole tissue.
    """
    if view not in VIEWS:
        raise InputError(f"unknown view {view!r}: one of {', '.join(VIEWS)}")
    last = _read(folder.frames[-1][1])
    pts = np.asarray(last.points)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo))
    cut_pts = None
    if view in ("cut", "overview") and folder.surfaces:
        surf = _read(folder.surfaces[-1][1])
        if surf.n_points >= 3:
            cut_pts = np.asarray(surf.points)
    if view in ("cut", "overview") and cut_pts is not None:
        inside = [s != "free" for s in folder.path_state]
        path = folder.path_tip[np.asarray(inside, bool)] if any(inside) else folder.path_tip
        focal = cut_pts.mean(axis=0)
        c = cut_pts - focal
        _, _, vt = np.linalg.svd(c, full_matrices=False)
        normal = vt[2]
        # up in the picture: the normal's side nearest superior (+z), else its largest component
        k = 2 if abs(normal[2]) > 0.3 else int(np.argmax(np.abs(normal)))
        normal = normal if normal[k] > 0 else -normal
        along = _unit(path[-1] - path[0]) if len(path) > 1 else vt[0]
        along = _unit(along - normal * float(along @ normal)) if np.linalg.norm(along) else vt[0]
        inward = _unit(np.cross(normal, along))
        if float(inward @ (centre - focal)) < 0:  # point into the tissue
            inward = -inward
        extent = float(np.ptp(c @ along)) if len(c) else 10.0
        if view == "cut":
            return Camera(focal, inward + 0.45 * normal, normal,
                          max(2.6 * extent, 0.25 * diag, CLOSE_UP_MIN * float(np.min(hi - lo))))
        return Camera(centre, inward + 0.3 * normal, normal, WHOLE * diag)
    if view in ("cut", "overview", "front"):
        return Camera(centre, np.array([0.0, 1.0, -0.25]), np.array([0.0, 0.0, 1.0]), WHOLE * diag)
    if view == "side":
        return Camera(centre, np.array([-1.0, 0.0, -0.2]), np.array([0.0, 0.0, 1.0]), WHOLE * diag)
    return Camera(centre, np.array([0.0, 0.25, -1.0]), np.array([0.0, -1.0, 0.0]), WHOLE * diag)


def _nice_length(span: float) -> float:
    """A round length (1, 2, 5 x 10^k mm) of about a fifth of ``span``."""
    target = max(span / 5.0, 1e-6)
    k = np.floor(np.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= target:
            return float(m * 10**k)
    return float(10**k)


def render_frame(frame_path, surface_path=None, path_done=None, path_all=None, camera: Camera | None = None,
                 title: str = "", size=(1200, 900), show_path: bool = True, label_names: dict | None = None):
    """Render one frame to an image.

    Parameters
    ----------
    frame_path : path-like
        Tissue frame (``frames/NNNN.vtu``): tets, ``texture_rgb`` or ``label``.
    surface_path : path-like, optional
        Cut surface at that frame (``surface/NNNN.vtp``).
    path_done, path_all : (k, 3) arrays, optional
        The blade's path up to this frame (solid) and in full (faint).
    camera : Camera
    title : str
        Shown in a band above the scene, never over the tissue.
    size : (width, height)
    label_names : dict, optional
        Material name of each tissue label, for the legend of an untextured model.

    Returns
    -------
    (height, width, 3) uint8
    """
    import pyvista as pv
    import vtk

    pv.OFF_SCREEN = True
    vtk.vtkLogger.SetStderrVerbosity(vtk.vtkLogger.VERBOSITY_ERROR)
    width, height = int(size[0]), int(size[1])
    grid = _read(frame_path)
    try:
        surf = grid.extract_surface(algorithm="dataset_surface")
    except TypeError:  # pyvista before the keyword existed
        surf = grid.extract_surface()

    pl = pv.Plotter(off_screen=True, window_size=[width, height], shape=(2, 1),
                    row_weights=[TITLE_BAND, 1.0 - TITLE_BAND], border=False)
    pl.set_background("white")
    # ---- title band
    pl.subplot(0, 0)
    pl.set_background("white")
    if title:
        pl.add_text(title, position=(0.012, 0.25), viewport=True, font_size=max(8, int(height / 75)), color="black")
    # ---- the scene
    pl.subplot(1, 0)
    pl.set_background("white")
    legend = []
    if "texture_rgb" in surf.point_data:
        pl.add_mesh(surf, scalars="texture_rgb", rgb=True, smooth_shading=True, split_sharp_edges=True,
                    feature_angle=60.0, specular=0.15, ambient=0.15)
        legend.append(["tissue (texture colours)", (0.55, 0.36, 0.28)])
    elif "label" in surf.cell_data and surf.n_cells:
        labels = np.asarray(surf.cell_data["label"])
        values = np.unique(labels)
        palette = [(0.87, 0.66, 0.58), (0.95, 0.85, 0.55), (0.75, 0.35, 0.35), (0.95, 0.95, 0.9),
                   (0.6, 0.75, 0.85), (0.7, 0.8, 0.6)]
        for i, v in enumerate(values):
            part = surf.extract_cells(np.flatnonzero(labels == v)).extract_surface(algorithm="dataset_surface")
            colour = palette[i % len(palette)]
            pl.add_mesh(part, color=colour, smooth_shading=True, split_sharp_edges=True, feature_angle=60.0,
                        specular=0.15, ambient=0.15)
            name = (label_names or {}).get(int(v))
            legend.append([f"{name} (label {int(v)})" if name else f"tissue label {int(v)}",
                           tuple(0.65 * c for c in colour)])
    else:
        pl.add_mesh(surf, color=TISSUE_COLOUR, smooth_shading=True, split_sharp_edges=True, feature_angle=60.0)
        legend.append(["tissue", tuple(0.65 * c for c in TISSUE_COLOUR)])

    rim_later = None
    if surface_path is not None:
        cut = _read(surface_path)
        if cut.n_cells:
            actor = pl.add_mesh(cut, color=CUT_COLOUR, smooth_shading=False, ambient=0.25, specular=0.05)
            # the cut faces are also faces of the tissue surface: drawn just in front of their
            # coincident tissue faces (a small offset), so the red shows where the wound's walls
            # are in sight, not through the skin around it
            mapper = actor.GetMapper()
            mapper.SetResolveCoincidentTopologyToPolygonOffset()
            mapper.SetRelativeCoincidentTopologyPolygonOffsetParameters(-1.0, -2.0)
            rim = cut.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False,
                                            non_manifold_edges=False)
            legend.append(["cut surface", CUT_COLOUR])
            if rim.n_cells:
                # the rim is drawn over the scene: where the tissue does not open (no prestress)
                # it is what shows where the blade went
                rim_actor = pl.add_mesh(rim, color=RIM_COLOUR, line_width=max(2.0, width / 500))
                rim_later = rim_actor
                legend.append(["cut outline (seen through)", RIM_COLOUR])

    overlay = [rim_later] if rim_later is not None else []
    if show_path and path_all is not None and len(path_all) > 1:
        # the tip runs inside the tissue: its path is drawn over the scene, not hidden by it
        step = max(1, len(path_all) // 400)
        faint = pv.lines_from_points(np.asarray(path_all, float)[::step])
        overlay.append(pl.add_mesh(faint, color=(0.55, 0.65, 0.9), line_width=max(1.5, width / 700)))
        if path_done is not None and len(path_done) > 1:
            done = pv.lines_from_points(np.asarray(path_done, float)[::step])
            overlay.append(pl.add_mesh(done, color=PATH_COLOUR, line_width=max(2.5, width / 400)))
            tip = pv.Sphere(radius=0.006 * (camera.distance if camera else 100.0), center=path_done[-1])
            overlay.append(pl.add_mesh(tip, color=PATH_COLOUR, lighting=False))
        legend.append(["blade tip path (seen through)", PATH_COLOUR])

    if camera is not None:
        pl.camera_position = camera.position()
        pl.camera.view_angle = 30.0
        # scale bar: a round length in the picture plane, low in the view
        span = 2.0 * camera.distance * np.tan(np.radians(15.0)) * width / max(height, 1)
        length = _nice_length(span)
        d = _unit(camera.view_dir)
        up = _unit(np.asarray(camera.up, float) - d * float(np.asarray(camera.up, float) @ d))
        right = _unit(np.cross(d, up))
        half_h = camera.distance * np.tan(np.radians(15.0))
        start = np.asarray(camera.focal, float) - 0.84 * half_h * up + 0.05 * span * right
        end = start + length * right
        # the focal point lies inside the tissue: the bar is drawn over the scene
        overlay.append(pl.add_mesh(pv.Line(start, end), color="black", line_width=max(3.0, width / 300)))
        label = f"{length:g} mm"
        pl.add_point_labels(np.array([0.5 * (start + end) + 0.05 * half_h * up]), [label], font_size=max(10, height // 60),
                            text_color="black", shape=None, show_points=False, always_visible=True)
    pl.add_axes(xlabel="x (L)", ylabel="y (P)", zlabel="z (S)", line_width=2, color="black")
    if legend:
        box = pl.add_legend(legend, bcolor=(1.0, 1.0, 1.0), border=True, face="rectangle")
        box.SetPosition(0.70, 0.97 - 0.055 * len(legend))
        box.SetPosition2(0.29, 0.055 * len(legend))
    if overlay:
        top = vtk.vtkRenderer()
        top.SetLayer(1)
        top.SetInteractive(0)
        top.SetViewport(pl.renderer.GetViewport())
        top.SetActiveCamera(pl.renderer.GetActiveCamera())
        pl.ren_win.SetNumberOfLayers(2)
        pl.ren_win.AddRenderer(top)
        for actor in overlay:
            pl.renderer.RemoveActor(actor)
            top.AddActor(actor)
    img = pl.screenshot(return_img=True)
    pl.close()
    return np.asarray(img)[..., :3].astype(np.uint8)
