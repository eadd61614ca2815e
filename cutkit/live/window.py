"""A live VTK window (pyvista): the textured tissue, the cut surface, the blade, the force and the rates.

The window is built on the first frame and then updated in place: the
tissue, the cut surface, the blade and the arrow keep their actors and
meshes; a frame only copies positions (and faces, when they changed) into
them and draws once.  It works on screen (``pyvista.Plotter`` with
``interactive_update``; events are processed at each frame) and off screen
(``off_screen=True``, no display needed), where every frame is drawn as on
screen and :meth:`WindowView.screenshot` returns the picture.

How a frame is drawn (``drawing``, :data:`DRAWINGS`): on a graphics card with
the plotter's multisampling and its five-light kit; on a software OpenGL
(Mesa's llvmpipe, where a frame of the demo knee at 1024 x 768 took 130-150
ms that way on a 2-core machine) without multisampling and with one light at
the camera, about 15-30 ms (docs/live.md, "Drawing").

With a :class:`~cutkit.live.sources.MouseKeyboardPoseSource` the window
hands it the user's input: a left-button drag that starts on the tissue
picks surface points (``vtkCellPicker``: point and normal) and steers the
blade; a drag that starts elsewhere moves the camera; ``x`` toggles cutting
with the mouse on and off; the source's keys (arrows, ``0``) set depth and
bevel (the arrows no longer zoom).
"""

from __future__ import annotations

import logging
import os
import time

import numpy as np

from cutkit.live.camera import CameraRig
from cutkit.live.views import LiveFrame, blade_quad

log = logging.getLogger("cutkit.live")

__all__ = ["WindowView", "CUT_RGB", "TISSUE_RGB", "DRAWINGS", "vertex_normals", "cut_colour_fraction",
           "software_opengl"]

#: Colour of the cut surface: a magenta that no tissue of the phantoms has.
CUT_RGB = (220, 30, 150)
#: Colour of the tissue where a frame has no texture.
TISSUE_RGB = (217, 153, 140)
#: Colour of the blade and of the force arrow.
BLADE_RGB = (60, 60, 70)
ARROW_RGB = (20, 120, 230)
#: Weight of the newest frame period in the fps estimate.
FPS_SMOOTHING = 0.1
#: How a window draws: ``"full"`` with the plotter's anti-aliasing (multisampling) and its light
#: kit; ``"fast"`` without multisampling, lit by one headlight (a light at the camera, which
#: follows the blade); ``"auto"`` fast on a software OpenGL (:func:`software_opengl`), else full.
DRAWINGS = ("auto", "full", "fast")
#: Words in OpenGL's renderer string that name a rasteriser running on the processor.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer", "gdi generic")
#: Height of the status lines, pixels.
STATUS_FONT_PX = 14


def software_opengl(capabilities: str) -> bool:
    """Whether a render window's capability report names a software rasteriser.

    Parameters
    ----------
    capabilities : str
        ``vtkRenderWindow.ReportCapabilities()`` of a window that has drawn once; its line
        ``OpenGL renderer string: ...`` names the rasteriser (e.g. ``llvmpipe (LLVM 15.0.6, 256
        bits)``).  A report without that line (no context yet) gives False.
    """
    for line in capabilities.splitlines():
        low = line.lower()
        if "renderer string" in low:
            return any(word in low for word in SOFTWARE_RENDERERS)
    return False


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals of a triangle mesh.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64

    Returns
    -------
    (n, 3) float32
        Unit normals; zero for points in no face.
    """
    from cutkit.live._kernels import vertex_normals as kernel

    points = np.ascontiguousarray(points, np.float64)
    faces = np.ascontiguousarray(faces, np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= points.shape[0]):
        raise IndexError("face index out of range")
    out = np.empty((points.shape[0], 3), np.float32)
    kernel(points, faces.reshape(-1, 3), out)
    return out


def cut_colour_fraction(image: np.ndarray, colour=CUT_RGB, min_saturation: float = 0.5,
                        hue_tolerance: float = 0.04) -> float:
    """Fraction of an image's pixels that show ``colour`` (its hue, any shading).

    Parameters
    ----------
    image : (h, w, 3) or (h, w, 4) uint8
    colour : 3 ints
    min_saturation : float
        Pixels less saturated than this (grey, white, shaded dark) do not count.
    hue_tolerance : float
        Largest hue difference, in turns (0 .. 0.5).

    Returns
    -------
    float
    """
    import colorsys

    rgb = image[..., :3].reshape(-1, 3).astype(np.float64) / 255.0
    mx, mn = rgb.max(axis=1), rgb.min(axis=1)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-12), 0.0)
    hue = _hue(rgb, mx, mn)
    target = colorsys.rgb_to_hsv(*(np.asarray(colour, np.float64) / 255.0))[0]
    d = np.abs(hue - target)
    d = np.minimum(d, 1.0 - d)
    hit = (sat >= min_saturation) & (d <= hue_tolerance) & (mx > 0.15)
    return float(hit.mean()) if hit.size else 0.0


def _hue(rgb, mx, mn):
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    c = np.maximum(mx - mn, 1e-12)
    h = np.where(mx == r, ((g - b) / c) % 6.0, np.where(mx == g, (b - r) / c + 2.0, (r - g) / c + 4.0))
    return (h / 6.0) % 1.0


def _cells(faces: np.ndarray) -> np.ndarray:
    cells = np.empty((faces.shape[0], 4), np.int64)
    cells[:, 0] = 3
    cells[:, 1:] = faces
    return cells.ravel()


class WindowView:
    """The live window.

    Parameters
    ----------
    off_screen : bool
        Render without a window (screenshots only; no display needed).
    window_size : (int, int)
    title : str
    pose_source : MouseKeyboardPoseSource, optional
        Receives mouse drags over the tissue and key presses.
    cut_rgb, tissue_rgb : 3 ints
        Colours of the cut surface and of untextured tissue.
    force_scale : float
        Length of the force arrow per newton, mm.
    background : str or 3 floats
    max_fps : float, optional
        Draw at most this many frames a second: a ``show`` sooner than that
        after the last drawn frame returns at once (None: draw every frame).
    camera : {"follow", "model", "fixed"}
        ``follow``: the camera follows the blade and the wound
        (:mod:`cutkit.live.camera`); ``model``: every frame shows the whole
        tissue; ``fixed``: the camera stays where it was put
        (``camera_position``, else the whole tissue at the start) and moves
        only with the mouse.
    camera_position : [position, focal point, up], optional
        The camera at the start (pyvista's ``camera_position``; 3 floats each).
    drawing : {"auto", "full", "fast"}
        How frames are drawn (:data:`DRAWINGS`); :attr:`drawn_as` says what ``"auto"`` chose
        once the window is built.
    """

    def __init__(self, off_screen: bool = False, window_size=(1024, 768), title: str = "cutkit live",
                 pose_source=None, cut_rgb=CUT_RGB, tissue_rgb=TISSUE_RGB, force_scale: float = 10.0,
                 background="white", max_fps: float | None = None, camera: str = "follow",
                 camera_position=None, drawing: str = "auto"):
        if drawing not in DRAWINGS:
            from cutkit.errors import InputError

            raise InputError(f"drawing must be one of {', '.join(DRAWINGS)}, not {drawing!r}")
        self.drawing = drawing
        self.drawn_as = None  # "full" or "fast" once the window is built
        self._rig = CameraRig(camera)
        self.camera_position = camera_position
        self.off_screen = bool(off_screen)
        self.window_size = tuple(int(v) for v in window_size)
        self.title = title
        self.source = pose_source
        self.cut_rgb = tuple(int(v) for v in cut_rgb)
        self.tissue_rgb = np.asarray(tissue_rgb, np.uint8)
        self.force_scale = float(force_scale)
        self.background = background
        self.min_period = 1.0 / max_fps if max_fps else 0.0
        self.cut_mode = pose_source is not None
        self.interactive = not self.off_screen  # events processed at each frame
        self.frames_shown = 0
        self.fps = 0.0
        self._pl = None
        self._last_render = None
        self._faces = (None, None)  # faces last uploaded (boundary, cut)
        self._n = -1
        self._rgb_key = None  # (buffer address, shape) of the colours last uploaded
        self._picker = None
        self._pressed = False

    # ------------------------------------------------------------------ building
    def _build(self, frame: LiveFrame) -> None:
        if not self.off_screen and os.environ.get("DISPLAY"):
            # VTK wheels that can render through EGL may pick it even under X (Xvfb), and an
            # EGL window cannot take the X interactor's events: ask for the X window (read when
            # VTK's rendering module loads, so this works only if nothing loaded it before)
            os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkXOpenGLRenderWindow")
        import pyvista as pv
        import vtk

        vtk.vtkLogger.SetStderrVerbosity(vtk.vtkLogger.VERBOSITY_ERROR)
        pl = pv.Plotter(off_screen=self.off_screen, window_size=list(self.window_size), title=self.title)
        pl.set_background(self.background)
        self._pl = pl
        self._tissue = pv.PolyData()
        self._cut = pv.PolyData()
        self._upload(frame)
        self._tissue_actor = pl.add_mesh(self._tissue, scalars="rgb", rgb=True, show_scalar_bar=False,
                                         name="tissue")
        self._cut_actor = pl.add_mesh(self._cut, color=self.cut_rgb, show_scalar_bar=False, name="cut")
        for actor in (self._tissue_actor, self._cut_actor):
            actor.prop.interpolation = "gouraud"
        self._cut_actor.prop.ambient = 0.3  # the wound's walls face away from the light: keep their colour
        self._blade = pv.PolyData(np.zeros((4, 3)), faces=np.array([4, 0, 1, 2, 3]))
        self._blade_actor = pl.add_mesh(self._blade, color=BLADE_RGB, specular=0.6, name="blade")
        arrow = pv.Arrow(start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0), tip_length=0.25, tip_radius=0.08,
                         shaft_radius=0.025, scale=1.0)
        self._arrow_base = np.array(arrow.points, np.float64)
        self._arrow = arrow
        self._arrow_actor = pl.add_mesh(arrow, color=ARROW_RGB, name="force")
        self._text = self._status_actor(pl)
        pl.reset_camera()
        if self.camera_position is not None:
            pl.camera_position = self.camera_position
        self._picker = vtk.vtkCellPicker()
        self._picker.SetTolerance(1e-4)
        self._picker.PickFromListOn()
        self._picker.AddPickList(self._tissue_actor)
        if not self.off_screen:
            pl.show(interactive_update=True, auto_close=False)
            self._install_input()
        else:
            pl.render_window.Render()  # the first picture: OpenGL's context and its renderer string
        self._choose_drawing(pl)

    @staticmethod
    def _status_actor(pl):
        """The status lines in the upper left corner: one text actor (a corner annotation scales
        its font again at every frame, 10-15 ms a frame on a software OpenGL)."""
        import vtk

        actor = vtk.vtkTextActor()
        prop = actor.GetTextProperty()
        prop.SetFontSize(STATUS_FONT_PX)
        prop.SetColor(0.0, 0.0, 0.0)
        prop.SetVerticalJustificationToTop()
        coord = actor.GetPositionCoordinate()
        coord.SetCoordinateSystemToNormalizedViewport()
        coord.SetValue(0.01, 0.99)
        pl.renderer.AddViewProp(actor)
        return actor

    def _choose_drawing(self, pl) -> None:
        """Draw as :attr:`drawing` says; ``"auto"`` reads the OpenGL renderer the window got."""
        fast = self.drawing == "fast" or (
            self.drawing == "auto" and software_opengl(pl.render_window.ReportCapabilities()))
        self.drawn_as = "fast" if fast else "full"
        if fast:
            import pyvista as pv

            pl.disable_anti_aliasing()
            pl.remove_all_lights()
            pl.add_light(pv.Light(light_type="headlight"))

    def _install_input(self) -> None:
        if self.source is None or self._pl.iren is None:
            return
        pl = self._pl
        for key in list(self.source.KEYS) + ["x"]:
            pl.clear_events_for_key(key)
            pl.add_key_event(key, lambda k=key: self._key(k))
        style = pl.iren.interactor.GetInteractorStyle()
        iren = pl.iren.interactor
        # observers on the style replace its own handling of these events
        style.AddObserver("LeftButtonPressEvent", lambda *_: self._vtk_press(style, iren))
        style.AddObserver("MouseMoveEvent", lambda *_: self._vtk_move(style, iren))
        style.AddObserver("LeftButtonReleaseEvent", lambda *_: self._vtk_release(style))

    def _vtk_press(self, style, iren):
        if not (self.cut_mode and self.on_press(*iren.GetEventPosition())):
            style.OnLeftButtonDown()

    def _vtk_move(self, style, iren):
        if self._pressed:
            self.on_move(*iren.GetEventPosition())
        else:
            style.OnMouseMove()

    def _vtk_release(self, style):
        if self._pressed:
            self.on_release()
        else:
            style.OnLeftButtonUp()

    def _key(self, key: str) -> None:
        if key == "x":
            self.cut_mode = not self.cut_mode
        elif self.source is not None:
            self.source.on_key(key)

    # ------------------------------------------------------------------ updating
    def _upload(self, frame: LiveFrame) -> None:
        """Copy the frame's geometry into the meshes; faces only when they changed."""
        import pyvista as pv

        n = frame.points.shape[0]
        if n != self._n:
            self._points = np.array(frame.points, np.float64)
            vtk_points = pv.vtk_points(self._points, deep=False)
            self._tissue.SetPoints(vtk_points)
            self._cut.SetPoints(vtk_points)
            self._vtk_points = vtk_points
            self._n = n
        else:
            self._points[:] = frame.points
            self._vtk_points.Modified()
        old_b, old_c = self._faces
        if old_b is None or not np.array_equal(old_b, frame.boundary_faces):
            self._tissue.faces = _cells(frame.boundary_faces)
            old_b = frame.boundary_faces.copy()
        if old_c is None or not np.array_equal(old_c, frame.cut_faces):
            self._cut.faces = _cells(frame.cut_faces)
            old_c = frame.cut_faces.copy()
        self._faces = (old_b, old_c)
        # the colours change only when nodes are added (a frame's rgb is a view of one growing
        # table): uploading them every frame cost as much as the normals
        key = (0, n) if frame.rgb is None else (frame.rgb.__array_interface__["data"][0], frame.rgb.shape)
        if key != self._rgb_key or "rgb" not in self._tissue.point_data:
            rgb = frame.rgb if frame.rgb is not None else np.broadcast_to(self.tissue_rgb, (n, 3))
            self._tissue.point_data["rgb"] = np.ascontiguousarray(rgb, np.uint8)
            self._rgb_key = key
        self._tissue.point_data.active_normals = vertex_normals(self._points, frame.boundary_faces)
        self._cut.point_data.active_normals = vertex_normals(self._points, frame.cut_faces)
        self._tissue.Modified()
        self._cut.Modified()

    def _update_tools(self, frame: LiveFrame) -> None:
        if frame.tip is None:
            self._blade_actor.visibility = False
            self._arrow_actor.visibility = False
            return
        self._blade_actor.visibility = True
        self._blade.points[:] = blade_quad(frame.tip, frame.a, frame.n, frame.blade_length, frame.blade_breadth)
        self._blade.Modified()
        f = np.asarray(frame.force, np.float64)
        length = float(np.linalg.norm(f)) * self.force_scale
        self._arrow_actor.visibility = length > 1e-6
        if length > 1e-6:
            d = f / np.linalg.norm(f)
            u = np.cross(d, np.eye(3)[int(np.argmin(np.abs(d)))])
            u /= np.linalg.norm(u)
            rot = np.column_stack([d, u, np.cross(d, u)])
            # drawn from the handle's end, where the hand holds the blade (the tip is in the tissue)
            handle = np.asarray(frame.tip, np.float64) - frame.blade_length * np.asarray(frame.a, np.float64)
            self._arrow.points[:] = (self._arrow_base * length) @ rot.T + handle
            self._arrow.Modified()

    def _aim(self, frame: LiveFrame) -> None:
        """Point the camera as its mode says (:class:`~cutkit.live.camera.CameraRig`)."""
        if self._pressed:
            return  # a mouse stroke steers the blade by what is under the pointer: the picture holds still
        pose = self._rig.update(frame)
        if pose is None:
            return
        renderer = self._pl.renderer
        if isinstance(pose, str):  # "fit": the whole tissue (not the blade, which may be far off)
            self._pl.reset_camera(render=False, bounds=self._tissue.bounds)
        else:
            # VTK's camera directly: pyvista's camera_position setter checks its input and resets
            # the clipping range once more, a few ms a frame at 30 fps on the development machine
            camera = renderer.GetActiveCamera()
            camera.SetPosition(*map(float, pose.position))
            camera.SetFocalPoint(*map(float, pose.focal_point))
            camera.SetViewUp(*map(float, pose.up))
            renderer.camera_set = True
        renderer.ResetCameraClippingRange()

    @property
    def status_text(self) -> str:
        """The status lines as last drawn (rates, session time, tets cut, force)."""
        return self._text.GetInput() if self._pl is not None else ""

    @property
    def camera_mode(self) -> str:
        return self._rig.mode

    def _status(self, frame: LiveFrame) -> str:
        r = frame.rates
        parts = [f"haptics {r['haptic_hz']:.0f} Hz" if "haptic_hz" in r else "haptics -",
                 f"relaxation {r['relax_passes_per_s']:.0f} passes/s" if "relax_passes_per_s" in r else "relaxation -",
                 f"{r['fps']:.0f} fps" if "fps" in r else (f"{self.fps:.0f} fps" if self.fps > 0 else "- fps")]
        line2 = (f"t {frame.t:.2f} s   tets cut {frame.tets_cut}   force {np.linalg.norm(frame.force):.2f} N"
                 + ("   [mouse cuts]" if self.cut_mode else ""))
        return "   ".join(parts) + "\n" + line2

    def show(self, frame: LiveFrame) -> None:
        """Draw ``frame`` (building the window on the first call) and process pending window events."""
        if self._last_render is not None and time.perf_counter() - self._last_render < self.min_period:
            return
        frame.check()
        if self._pl is None:
            self._build(frame)
        elif self.closed:
            return
        else:
            self._upload(frame)
        self._update_tools(frame)
        self._aim(frame)
        self._text.SetInput(self._status(frame))
        if self.off_screen:
            # pyvista's render() draws nothing before its show(), which an off-screen window never
            # calls: draw through VTK, so that off screen every frame costs what it does on screen
            self._pl.render_window.Render()
        elif not self.interactive:
            self._pl.render()
        else:
            try:
                self._pl.update(1, force_redraw=True)
            except Exception as err:  # pyvista's MismatchedInteractorError: an EGL window under X
                log.warning("the window cannot process events (%s); drawing without interaction. "
                            "Set VTK_DEFAULT_OPENGL_WINDOW=vtkXOpenGLRenderWindow before starting.",
                            str(err).split(".")[0])
                self.interactive = False
                self._pl.render()
        now = time.perf_counter()
        if self._last_render is not None and now > self._last_render:
            rate = 1.0 / (now - self._last_render)
            self.fps = rate if self.fps == 0.0 else (1 - FPS_SMOOTHING) * self.fps + FPS_SMOOTHING * rate
        self._last_render = now
        self.frames_shown += 1

    def idle(self) -> None:
        """A frame left out (nothing moved): the window's pending events are processed, nothing is
        drawn (the interactor draws a camera the mouse moves itself)."""
        if self._pl is None or self.closed or self.off_screen or not self.interactive:
            return
        try:
            self._pl.iren.process_events()
        except Exception as err:  # as show(): an EGL window under X takes no events
            log.warning("the window cannot process events (%s); drawing without interaction.",
                        str(err).split(".")[0])
            self.interactive = False

    # ------------------------------------------------------------------ input
    def pick(self, x: int, y: int):
        """The tissue surface under display pixel (x, y) (origin bottom left).

        Returns
        -------
        (point (3,) float64, normal (3,) float64) or None
        """
        if self._pl is None or not self._picker.Pick(x, y, 0, self._pl.renderer):
            return None
        point = np.array(self._picker.GetPickPosition(), np.float64)
        normal = np.array(self._picker.GetPickNormal(), np.float64)
        cam = np.array(self._pl.camera.position) - point
        if np.dot(normal, cam) < 0:  # the side facing the viewer is "out"
            normal = -normal
        return point, normal

    def _screen_right(self) -> np.ndarray:
        cam = self._pl.camera
        view = np.array(cam.focal_point) - np.array(cam.position)
        return np.cross(view, np.array(cam.up))

    def on_press(self, x: int, y: int) -> bool:
        """A left-button press at display (x, y); True if it started a stroke on the tissue."""
        hit = self.pick(x, y) if self.source is not None else None
        if hit is None:
            return False
        self.source.on_press(hit[0], hit[1], edge=self._screen_right())
        self._pressed = True
        return True

    def on_move(self, x: int, y: int) -> None:
        """The pointer moved to display (x, y) during a stroke."""
        hit = self.pick(x, y)
        if hit is not None:
            self.source.on_drag(hit[0], hit[1])

    def on_release(self) -> None:
        """The left button was let go: the stroke ends."""
        self._pressed = False
        if self.source is not None:
            self.source.on_release()

    # ------------------------------------------------------------------ output
    def world_to_display(self, point) -> tuple[float, float]:
        """Display coordinates (origin bottom left) of a world point, for tests and tools."""
        ren = self._pl.renderer
        ren.SetWorldPoint(*map(float, point), 1.0)
        ren.WorldToDisplay()
        x, y, _ = ren.GetDisplayPoint()
        return x, y

    def screenshot(self, path=None) -> np.ndarray:
        """The last frame as an (h, w, 3) uint8 image; also written to ``path`` (PNG) if given."""
        img = self._pl.screenshot(None if path is None else str(path), return_img=True)
        return np.asarray(img)[..., :3]

    @property
    def closed(self) -> bool:
        """True once the user closed the window (or :meth:`close` was called)."""
        return self._pl is not None and (getattr(self._pl, "_closed", False) or self._pl.render_window is None)

    def close(self) -> None:
        if self._pl is not None and not self.closed:
            self._pl.close()
