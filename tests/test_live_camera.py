"""The live window's camera modes (cutkit.live.camera): follow the blade and the wound, whole model, fixed."""

import sys
from pathlib import Path

import numpy as np
import pytest

from cutkit.errors import InputError
from cutkit.live.camera import VIEW_ANGLE_DEG, CameraPose, CameraRig, follow_view

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_live_views import slab_with_wound  # noqa: E402


def _wound(frame):
    return frame.points[frame.cut_faces.ravel()]


def test_follow_looks_at_the_blade_from_outside_across_the_blade_plane():
    f = slab_with_wound()
    pose = follow_view(f.tip, f.a, f.n, _wound(f), f.blade_length)
    off = pose.position - pose.focal_point
    direction = off / np.linalg.norm(off)
    b = np.cross(f.n, f.a)
    assert np.linalg.norm(pose.focal_point - f.tip) < f.blade_length  # near the blade
    assert direction @ -f.a > 0.5  # from the handle's side: outside the skin
    assert abs(direction @ b) > 0.3  # tilted across the blade plane: one wall of the wound faces it
    assert abs(pose.up @ direction) < 1e-9 and np.isclose(np.linalg.norm(pose.up), 1.0)
    # the wound is inside the view cone
    half = np.radians(VIEW_ANGLE_DEG) / 2.0
    for p in _wound(f):
        v = p - pose.position
        assert np.arccos(np.clip(v @ -direction / np.linalg.norm(v), -1, 1)) < half


def test_the_rig_modes():
    f = slab_with_wound()
    with pytest.raises(InputError, match="camera must be one of"):
        CameraRig("orbit")
    assert CameraRig("model").update(f) == "fit"
    assert CameraRig("fixed").update(f) is None
    rig = CameraRig("follow", ease=0.25)
    target = follow_view(f.tip, f.a, f.n, _wound(f), f.blade_length)
    first = rig.update(f)
    assert isinstance(first, CameraPose) and np.allclose(first.position, target.position)
    # the blade moves 10 mm along the wound: the camera goes part of the way at each frame, then arrives
    f.tip = f.tip + np.array([0.0, 10.0, 0.0])
    moved = follow_view(f.tip, f.a, f.n, _wound(f), f.blade_length)
    step = rig.update(f)
    d0 = np.linalg.norm(target.focal_point - moved.focal_point)
    assert 0.0 < np.linalg.norm(step.focal_point - moved.focal_point) < d0
    for _ in range(100):
        last = rig.update(f)
    assert np.allclose(last.position, moved.position, atol=1e-6)
    assert np.allclose(last.focal_point, moved.focal_point, atol=1e-6)


def test_without_a_blade_follow_frames_the_model_then_keeps_to_the_wound():
    f = slab_with_wound()
    f.tip = f.a = f.n = None
    assert CameraRig("follow").update(f) == "fit"  # nothing to follow yet


def _window_after(frame, frames=20, **kw):
    from cutkit.live.window import WindowView, cut_colour_fraction

    view = WindowView(off_screen=True, window_size=(320, 240), **kw)
    try:
        for _ in range(frames):
            view.show(frame)
        cam = view._pl.camera
        return (np.array(cam.focal_point), np.array(cam.position),
                cut_colour_fraction(view.screenshot()), view.camera_mode)
    finally:
        view.close()


def test_the_window_follows_by_default_and_shows_more_wound_than_the_whole_model():
    pv = pytest.importorskip("pyvista")
    pv.OFF_SCREEN = True
    f = slab_with_wound()
    focal, _, follow_px, mode = _window_after(f)
    assert mode == "follow"
    assert np.linalg.norm(focal - f.tip) < f.blade_length
    model_focal, _, model_px, _ = _window_after(f, camera="model")
    lo, hi = f.points.min(axis=0), f.points.max(axis=0)
    assert np.allclose(model_focal[:2], 0.5 * (lo + hi)[:2], atol=1.0)  # the whole tissue's centre
    assert follow_px > 2.0 * model_px > 0.0


def test_a_fixed_camera_stays_where_it_was_put():
    pv = pytest.importorskip("pyvista")
    pv.OFF_SCREEN = True
    f = slab_with_wound()
    put = [(0.0, -60.0, 30.0), (0.0, 0.0, -2.0), (0.0, 0.0, 1.0)]
    focal, position, _, mode = _window_after(f, frames=5, camera="fixed", camera_position=put)
    assert mode == "fixed"
    assert np.allclose(position, put[0]) and np.allclose(focal, put[1])
    with pytest.raises(InputError, match="camera must be one of"):
        _window_after(f, frames=1, camera="orbit")
