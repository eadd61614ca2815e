"""``cutkit render OUT/``: pictures and a movie of an output folder, in any view."""

import click


@click.command(name="render")
@click.argument("out_dir", metavar="OUT", type=click.Path(file_okay=False))
@click.option("--view", "views", multiple=True, type=click.Choice(["cut", "overview", "front", "side", "top"]),
              help="View of the pictures (repeatable) [default: cut]: cut looks into the wound, overview "
                   "frames the whole tissue along the cut, front/side/top from -y, +x, +z (LPS).")
@click.option("--movie", default=None, metavar="FILE",
              help="Also a movie of every frame in the first view: FILE.mp4 (H.264) or FILE.gif, "
                   "relative to OUT.")
@click.option("--no-png", is_flag=True, help="No pictures (with --movie: the movie only).")
@click.option("--size", default=None, metavar="WxH",
              help="Size of the pictures and the movie in pixels [default: 1200x900 pictures, 960x720 movie].")
@click.option("--fps", default=None, type=float, help="Movie frames per second [default: the run's, real time].")
def command(out_dir, views, movie, no_png, size, fps):
    """Render OUT (a folder of `cutkit simulate` or `cutkit demo`) again: key-frame pictures
    under OUT/pictures/ and, with --movie, a movie of the whole cut."""
    from cutkit.cli._ui import progress, say
    from cutkit.errors import InputError
    from cutkit.io.atomic import check_writable
    from cutkit.render import read_folder, render_output

    try:
        w, h = (int(v) for v in (size or "1200x900").lower().split("x"))
    except ValueError:
        w = h = 0
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise InputError(f"--size must be WIDTHxHEIGHT in pixels (16..8192), e.g. 1200x900 (got {size!r})")
    if fps is not None and not (fps > 0 and fps < 1000):
        raise InputError(f"--fps must be a positive number below 1000, got {fps:g}")
    if movie is not None and not movie.lower().endswith((".mp4", ".gif")):
        raise InputError(f"--movie must name a .mp4 or .gif file (got {movie!r})")
    if no_png and movie is None:
        raise InputError("--no-png without --movie leaves nothing to render")
    read_folder(out_dir)  # a clear error before anything is written
    check_writable(f"{out_dir}/pictures", folder=True)
    views = tuple(views) or ("cut",)
    with progress() as bar:
        task = bar.add_task("rendering", total=None)
        sizes = {"size": (w, h)} if size is None else {"size": (w, h), "movie_size": (w, h)}
        done = render_output(out_dir, pictures=not no_png, views=views, movie=movie, movie_fps=fps, **sizes, progress=lambda k, n: bar.update(task, completed=k, total=n))
    for p in done["pictures"]:
        say(f"picture: {out_dir}/{p}")
    if done["movie"]:
        say(f"movie: {out_dir}/{done['movie']}" if not done["movie"].startswith("/") else f"movie: {done['movie']}")
