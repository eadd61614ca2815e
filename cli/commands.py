"""The one table of cutkit commands.

Each entry names the module that defines the command (a ``click.Command``
or ``click.Group`` called ``command``) and the one-line help shown by
``cutkit --help``.  The module is imported only when its command runs, so
``cutkit --help`` stays fast and heavy libraries load only where needed.
"""

COMMANDS: dict[str, tuple[str, str]] = {
    # mesh authoring
    "import": ("cutkit.cli.import_mesh", "Import a tetrahedral mesh (gmsh, TetGen, VTK, ...) into a model file."),
    "info": ("cutkit.cli.info", "Describe a volume or a model file."),
    "check": ("cutkit.cli.check", "Check a model's mesh: indices, orientation, manifold boundary, hanging nodes, quality."),
    "export": ("cutkit.cli.export", "Export a model's mesh to .vtu, .vtk, .msh, .xdmf, ... by extension."),
    "segment": ("cutkit.cli.segment", "Segment a volume into a label map (threshold, Otsu, colour channel, labels)."),
    "isovolume": ("cutkit.cli.isovolume", "Tetrahedralise a label map with the six-tetrahedra marching isovolume."),
    "decimate": ("cutkit.cli.decimate", "Progressively decimate a model by interior edge collapses."),
    "assign": ("cutkit.cli.assign", "Assign materials, boundary conditions and prestress from a recipe."),
    "texture": ("cutkit.cli.texture", "Register a 3D texture volume to a model and store texture coordinates."),
    "build-model": ("cutkit.cli.build_model", "Run the whole build: volume -> segmentation -> mesh -> model.h5."),
    # runtime
    "cut": ("cutkit.cli.cut", "Cut a model kinematically along a blade trajectory."),
    "relax": ("cutkit.cli.relax", "Relax a model under prestress, boundary conditions and gravity."),
    "simulate": ("cutkit.cli.simulate", "Cut and relax a model along a trajectory with the scalpel force model."),
    "trajectory": ("cutkit.cli.trajectory", "Write the trajectory of a straight or arc incision."),
    "sweep": ("cutkit.cli.sweep", "Run a parameter study of many simulations on Dask (local or an existing cluster)."),
    "live": ("cutkit.cli.live", "Cut a model live (haptic device, mouse, 3D Slicer) and record the session."),
    "haptics": ("cutkit.cli.haptics", "The 1 kHz haptic scalpel service and its benchmark client."),
    "demo": ("cutkit.cli.demo", "Build the knee phantom and cut it along the shipped incision."),
    "render": ("cutkit.cli.render", "Render an output folder again: pictures in other views, a movie of the cut."),
}
