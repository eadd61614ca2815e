"""Pictures and movies of an output folder (cutkit.render, `cutkit render`, simulate --png/--movie)."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from cutkit.cli.main import cli
from cutkit.errors import InputError
from cutkit.io.series import SeriesWriter
from cutkit.mesh.generate import box_mesh
from cutkit.render import camera_for, read_folder, render_output
from cutkit.render.scene import CUT_COLOUR
from cutkit.simulate.outputs import FORCE_COLUMNS, ForceLog, SurfaceSeries

N_FRAMES = 4


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder laid out as simulate writes it: a slab whose exposed cut face (on its top, z = 8) grows
    frame by frame."""
    out = tmp_path_factory.mktemp("run")
    points, tets = box_mesh((10, 6, 4), spacing=(2.0, 2.0, 2.0))
    labels = np.ones(len(tets), np.int32)
    log = ForceLog(100)
    with SeriesWriter(out, "cut") as series:
        surface = SurfaceSeries(out)
        for k in range(N_FRAMES):
            t = 0.1 * k
            x1 = 2.0 + 4.0 * k
            # the cut surface: a quad from x = 2 to x1, y from 4 to 8, on the top face z = 8
            quad = np.array([[2.0, 4.0, 8.0], [x1, 4.0, 8.0], [x1, 8.0, 8.0], [2.0, 8.0, 8.0]])
            pts = np.vstack([points, quad])
            n = len(points)
            faces = np.array([[n, n + 1, n + 2], [n, n + 2, n + 3]]) if k else np.zeros((0, 3), np.int64)
            series.write(t, points, tets, point_data={"displacement": np.zeros_like(points)},
                         cell_data={"label": labels})
            surface.write(t, pts, faces)
            for j in range(10):
                tip = np.array([2.0 + 0.4 * (10 * k + j), 6.0, 6.0])
                log.add(t + 0.01 * j, 2 if k else 0, np.array([0.0, 0.5, 0.0]), 0.0, 0.0, 0.0, tip, tip)
        surface.close()
    log.write(out / "forces.csv")
    (out / "summary.json").write_text(json.dumps({"cut_tets": 12, "options": {"fps": 10.0},
                                                  "cut_opening_mm": {"final_mean": 0.5}, "pictures": []}))
    return out


def test_folder_is_read_back(folder):
    f = read_folder(folder)
    assert len(f.frames) == len(f.surfaces) == N_FRAMES
    assert f.path_tip.shape == (10 * N_FRAMES, 3) and f.path_state[0] == "free"
    assert "forces.csv" and list(FORCE_COLUMNS)[:2] == ["t", "state"]


def test_cut_view_looks_into_the_cut(folder):
    cam = camera_for(read_folder(folder), "cut")
    # the cut lies in the plane z = 8: the camera's up is its normal, the focal point on it
    assert abs(abs(cam.up[2]) - 1.0) < 1e-6
    assert abs(cam.focal[2] - 8.0) < 1e-6


def _red_pixels(img):
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return int(np.count_nonzero((r > 90) & (r > 2.5 * g) & (r > 2.5 * b)))


def test_pictures_show_the_cut_in_its_own_colour(folder):
    import imageio.v3 as iio

    done = render_output(folder, views=("top", "cut"), size=(480, 360))
    assert done["pictures"][-1] == "pictures/0003_cut.png" and len(done["pictures"]) in (4, 6)
    img = iio.imread(folder / done["pictures"][-1])
    assert img.shape[:2] == (360, 480)
    top = iio.imread(folder / "pictures" / "0003_top.png")
    assert _red_pixels(top[..., :3]) > 1000  # the cut surface, in CUT_COLOUR over the coincident tissue faces
    assert CUT_COLOUR[0] > 2.5 * CUT_COLOUR[1]
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["pictures"] == done["pictures"]


@pytest.mark.parametrize("name", ["m.gif", "m.mp4"])
def test_movie_has_every_frame(folder, name):
    import imageio.v3 as iio

    done = render_output(folder, pictures=False, movie=name, movie_size=(320, 240))
    assert done["movie"] == name and done["pictures"] == []
    frames = iio.imread(folder / name, index=None) if name.endswith(".gif") else \
        np.stack(list(iio.imiter(folder / name, plugin="pyav"))) if _has_pyav() else None
    if frames is not None:
        assert len(frames) == N_FRAMES
    assert (folder / name).stat().st_size > 1000


def _has_pyav():
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


def test_render_command(folder):
    r = CliRunner().invoke(cli, ["render", str(folder), "--view", "top", "--size", "320x240", "--movie", "c.gif"])
    assert r.exit_code == 0, r.output
    assert f"picture: {folder}/pictures/0003_top.png" in r.output
    assert (folder / "c.gif").is_file()


def test_render_of_a_folder_that_is_not_an_output(tmp_path):
    with pytest.raises(InputError, match=r"not an output folder of cutkit simulate \(no cut.pvd\)$"):
        read_folder(tmp_path)
    r = CliRunner().invoke(cli, ["render", str(tmp_path), "--size", "big"])
    assert r.exit_code == 2 and "--size must be WIDTHxHEIGHT" in r.output


def test_a_cut_that_does_not_open_still_shows(folder, tmp_path):
    """No prestress (a brain): the lips stay closed inside the tissue; the outline is drawn through it."""
    from cutkit.render import render_frame
    from cutkit.render.scene import Camera, RIM_COLOUR

    points, _ = box_mesh((10, 6, 4), spacing=(2.0, 2.0, 2.0))
    quad = np.array([[4.0, 6.0, 2.0], [16.0, 6.0, 2.0], [16.0, 6.0, 6.0], [4.0, 6.0, 6.0]])  # inside, y = 6
    surface = SurfaceSeries(tmp_path)
    path = surface.write(0.0, np.vstack([points, quad]), np.array([[len(points) + i for i in (0, 1, 2)],
                                                                   [len(points) + i for i in (0, 2, 3)]]))
    frame = read_folder(folder).frames[-1][1]
    cam = Camera(focal=np.array([10.0, 6.0, 4.0]), view_dir=np.array([0.0, 0.0, -1.0]), up=np.array([0.0, 1.0, 0.0]),
                 distance=40.0)
    img = render_frame(frame, path, camera=cam, size=(480, 360), show_path=False)
    rim = np.array(RIM_COLOUR) * 255
    scene = (slice(40, 360), slice(0, 320))  # left of the legend, below the title
    near = np.abs(img[scene].astype(float) - rim).max(axis=2) < 40
    assert near.sum() > 100  # the outline of the hidden cut
    hidden = render_frame(frame, None, camera=cam, size=(480, 360), show_path=False)
    assert (np.abs(hidden[scene].astype(float) - rim).max(axis=2) < 40).sum() < 10


def test_a_hand_that_holds_still_is_titled_at_rest(tmp_path):
    """The scalpel model keeps "cutting" while the hand rests after a stroke; the picture's title
    says "blade at rest" once the tip has not moved over REST_WINDOW_S, and "cutting" while it moves."""
    from cutkit.render.folder import REST_WINDOW_S, Folder
    from cutkit.render.output import _title

    t = np.arange(0.0, 0.5, 0.001)
    tip = np.stack([np.minimum(t, 0.3) * 10.0, np.zeros_like(t), np.zeros_like(t)], axis=1)  # stops at 0.3 s
    f = Folder(path=tmp_path, frames=[(0.0, None)], path_t=t, path_tip=tip, path_state=["cutting"] * t.size,
               force=np.zeros(t.size))
    assert "cutting" in _title(f, 0.2) and "at rest" not in _title(f, 0.2)
    assert "cutting" in _title(f, 0.3 + 0.5 * REST_WINDOW_S)  # stopped, but not for the whole window yet
    assert "blade at rest" in _title(f, 0.3 + 2 * REST_WINDOW_S)


def test_the_close_up_of_a_small_model_shows_its_outline(tmp_path):
    """A short cut on a small model: the cut view stands back far enough that the picture spans
    most of the model (its smallest side), not a patch of its surface."""
    from cutkit.render.scene import CLOSE_UP_MIN

    out = tmp_path / "run"
    points, tets = box_mesh((5, 5, 5), spacing=(2.0, 2.0, 2.0))  # a 10 mm cube
    quad = np.array([[4.0, 4.0, 10.0], [5.0, 4.0, 10.0], [5.0, 6.0, 10.0], [4.0, 6.0, 10.0]])  # a 1 mm cut on top
    n = len(points)
    with SeriesWriter(out, "cut") as series:
        surface = SurfaceSeries(out)
        series.write(0.0, points, tets, point_data={"displacement": np.zeros_like(points)},
                     cell_data={"label": np.ones(len(tets), np.int32)})
        surface.write(0.0, np.vstack([points, quad]), np.array([[n, n + 1, n + 2], [n, n + 2, n + 3]]))
        surface.close()
    log = ForceLog(100)
    for j in range(5):
        tip = np.array([4.0 + 0.25 * j, 5.0, 9.0])
        log.add(0.01 * j, 2, np.zeros(3), 0.0, 0.0, 0.0, tip, tip)
    log.write(out / "forces.csv")
    (out / "summary.json").write_text(json.dumps({"cut_tets": 1, "options": {"fps": 10.0}, "pictures": []}))
    cam = camera_for(read_folder(out), "cut")
    assert cam.distance >= CLOSE_UP_MIN * 10.0 - 1e-9
    high = 2.0 * cam.distance * np.tan(np.radians(15.0))  # the picture's height at the focal plane (30 degrees)
    assert high >= 0.55 * 10.0
