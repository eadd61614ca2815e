"""Shared terminal helpers of the command modules (rich console, tables, progress)."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

# soft_wrap: plain lines are never broken by rich, so a long file path stays
# one piece to copy (the terminal wraps it for display); tables still fit the width.
console = Console(highlight=False, soft_wrap=True)


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


def table(title: str, columns: list[str], rows: list[list]) -> Table:
    """A rich table of ``rows`` under ``columns``."""
    t = Table(title=title, title_justify="left")
    for c in columns:
        t.add_column(c)
    for r in rows:
        t.add_row(*[str(v) for v in r])
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
