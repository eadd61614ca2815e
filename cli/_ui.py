"""Shared terminal helpers of the command modules (rich console, tables, progress)."""

from __future__ import annotations

import contextlib
import os

import click
from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

#: Console width when the output is not a terminal (tables are never cut).
PIPED_WIDTH = 400

# soft_wrap: plain lines are never broken by rich, so a long file path stays
# one piece to copy (the terminal wraps it for display); tables still fit the width.
console = Console(highlight=False, soft_wrap=True)
if not console.is_terminal and "COLUMNS" not in os.environ:
    # piped or redirected: rich would cut tables to 80 columns; a file has no width
    console = Console(highlight=False, soft_wrap=True, width=PIPED_WIDTH)


def esc(value) -> str:
    """``value`` as text that rich prints as it is: user paths and names are never markup."""
    from rich.markup import escape

    return escape(str(value))


def say(text: str) -> None:
    """Print a plain line (no rich markup in it: brackets in paths and names stay)."""
    console.print(text, markup=False)


def warn(text: str) -> None:
    """Print ``warning: TEXT`` (TEXT plain, never markup)."""
    console.print("[yellow]warning:[/] " + esc(text))


def note(text: str) -> None:
    """Print ``note: TEXT`` (TEXT plain, never markup)."""
    console.print("[yellow]note:[/] " + esc(text))


def overwrite_option(command):
    """The ``--overwrite`` flag of the commands that write a folder."""
    return click.option("--overwrite", is_flag=True,
                        help="Replace the outputs of an earlier run in the output folder (only the files and "
                             "folders this command writes; anything else there is kept). Without it a "
                             "non-empty output folder is refused.")(command)


#: ``--solver``'s choices and default: :data:`cutkit.relax.elastic_tissue.SOLVERS` and
#: ``DEFAULT_SOLVER`` (kept here so that the CLI's startup imports no kernels; a test holds them equal).
SOLVER_CHOICES = ("newton", "vbd", "hybrid")
SOLVER_DEFAULT = "hybrid"


def solver_option(command):
    """The ``--solver`` option of the commands that relax an element model (simulate, demo, live)."""
    return click.option("--solver", type=click.Choice(SOLVER_CHOICES), default=None,
                        help="How the element model's relaxation steps are solved: projected Newton, vertex "
                             "block descent, or vertex block descent with a local Newton polish of a step left "
                             "unconverged and resting steps solved by Newton to 3e-4 of the force scale under the "
                             "blade (1e-3, then 1e-4 once it has left) "
                             f"[default: {SOLVER_DEFAULT}].")(command)


@contextlib.contextmanager
def folder_guard(path):
    """Remove ``path`` again when the command fails and leaves it as it found it: missing, or created empty.

    A run stopped by Ctrl-C or SIGTERM keeps what it wrote (a valid recording)."""
    from pathlib import Path

    existed = Path(path).exists()
    try:
        yield
    except KeyboardInterrupt:
        raise
    except BaseException:
        if not existed:
            _remove_empty_tree(Path(path))
        raise


def _remove_empty_tree(path) -> None:
    """Remove ``path`` and its sub-folders where they hold no file (bottom up)."""
    if not path.is_dir():
        return
    for root, _dirs, _files in sorted(os.walk(path), key=lambda w: -len(w[0])):
        with contextlib.suppress(OSError):
            os.rmdir(root)


def progress() -> Progress:
    """A progress display for long work (goes quiet when not on a terminal)."""
    return Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        console=console,
        transient=False,
    )


def stage_reporter(bar: Progress, task):
    """``on_stage(name, event)`` for :func:`cutkit.build.run_build` that drives a progress task."""

    def on_stage(name, event):
        if event == "start":
            bar.update(task, description=f"build-model: {name}")
        else:
            bar.advance(task)

    return on_stage


def print_crumbs_note(cm) -> None:
    """Tell the crumbs the cut removed and the larger pieces it set loose (``cutkit.cutting.crumbs``), if any."""
    from cutkit.cutting.crumbs import CRUMB_VOLUME_FRACTION, crumb_volume, loose_pieces

    if cm.crumb_count:
        note(f"{cm.crumb_count} crumb{'s' * (cm.crumb_count != 1)} cut loose (each at most "
             f"{CRUMB_VOLUME_FRACTION:g} of the model's volume) removed: {crumb_volume(cm):.4g} mm^3")
    loose = loose_pieces(cm)[1:]
    if loose.size:
        note(f"{loose.size} piece{'s' * (loose.size != 1)} cut loose besides the largest: "
             + ", ".join(f"{v:.4g}" for v in loose[:10]) + (" ..." if loose.size > 10 else "") + " mm^3")


def missed_message(points, tips) -> str:
    """The warning of a blade that never cut: the model's extents and the trajectory's, in mm."""
    from cutkit.simulate.record import extents_text

    return f"the blade never cut the tissue: no tet was cut ({extents_text(points, tips)})"


def table(title: str, columns: list[str], rows: list[list]) -> Table:
    """A rich table of ``rows`` under ``columns``."""
    from rich.markup import escape

    # cells are plain text: "[deg]" is a unit, not rich markup
    t = Table(title=escape(title), title_justify="left")
    for c in columns:
        t.add_column(escape(c))
    for r in rows:
        t.add_row(*[escape(str(v)) for v in r])
    return t


def parse_vec3(text: str | None, what: str):
    """Parse ``"X,Y,Z"`` into three floats (None passes through)."""
    if text is None:
        return None
    from cutkit.errors import InputError

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3:
        raise InputError(f"{what} must be three comma-separated numbers, e.g. 1,1,2.5 (got {text!r})")
    return values


#: Endings of a model file (HDF5); anything else is another tool's format, written by ``cutkit export``.
MODEL_SUFFIXES = (".h5", ".hdf5")


def check_model_output(path) -> None:
    """Raise InputError unless ``path`` ends like a model file (.h5)."""
    from pathlib import Path

    from cutkit.errors import InputError

    suffix = Path(path).suffix.lower()
    if suffix not in MODEL_SUFFIXES:
        raise InputError(f"{path}: a model file ends in .h5; to get {suffix or 'another format'}, "
                         f"write MODEL.h5 and run `cutkit export MODEL.h5 {path}`")


def warn_missing_geometry(path, spacing) -> None:
    """Say so when a volume format without voxel size (.npy, TIFF) is read without --spacing."""
    if spacing is not None:
        return
    from cutkit.volumes.registry import format_for

    try:
        fmt = format_for(path)
    except Exception:  # the reader reports unknown formats itself
        return
    if fmt.name in ("numpy", "tiff", "tiff-folder"):
        warn(f"{path} stores no voxel size: taking 1 x 1 x 1 mm voxels (give --spacing SX,SY,SZ in mm)")
