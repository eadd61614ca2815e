"""Pictures and movies of what a cut did, rendered from an output folder.

Everything is read back from the files ``cutkit simulate`` (and ``cutkit
demo``) writes: the tissue frames (``cut.pvd``), the cut surface
(``cut_surface.pvd``), the blade's path (``forces.csv``) and the counts
(``summary.json``), so any folder can be rendered again later with other
views (``cutkit render OUT/``).

A picture shows the tissue surface smooth-shaded in its texture colours (or
one colour per tissue label), the cut surface in its own colour with its
rim outlined (visible even where the tissue does not open), the blade's
path, a scale bar, the LPS axes, a legend and a title above the scene.
"""

from cutkit.render.folder import Folder, read_folder
from cutkit.render.scene import VIEWS, Camera, camera_for, render_frame
from cutkit.render.output import render_output, write_movie

__all__ = ["Folder", "read_folder", "VIEWS", "Camera", "camera_for", "render_frame", "render_output", "write_movie"]
