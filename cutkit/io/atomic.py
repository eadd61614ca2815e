"""Write outputs so that a reader never sees a half-written file.

Every output is first written to a temporary file in the destination's
folder and renamed over the destination only once complete; ``os.replace``
is atomic on POSIX and Windows when both paths are on one file system.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from cutkit.errors import InputError


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None):
    """Yield a temporary path beside ``path``; rename it to ``path`` on success.

    Parameters
    ----------
    path : path-like
        The final output file.  Its folder is created if missing.
    suffix : str, optional
        Suffix of the temporary file (defaults to that of ``path`` so that
        writers that pick a format by extension still work).

    On an exception (including KeyboardInterrupt) the temporary file is
    removed and ``path`` is left as it was.
    """
    path = Path(path)
    if suffix is None:
        suffix = "".join(path.suffixes) or ".tmp"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror or exc}") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp makes the file private (0600); give it the permissions any
        # other new file would get, so outputs are readable as usual
        os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def check_writable(path: str | os.PathLike, folder: bool = False) -> None:
    """Raise :class:`InputError` unless ``path`` can be written; call before the work.

    Parameters
    ----------
    path : path-like
        An output file (``folder=False``) or an output folder (``folder=True``).
        Missing folders on the way count as writable when the nearest existing
        one is: outputs create them.

    The nearest existing folder must be a folder, allow writing (``os.access``)
    and take a probe file (which catches read-only and immutable folders and
    file systems that ``os.access`` does not see).
    """
    p = Path(path)
    if folder:
        if p.exists() and not p.is_dir():
            raise InputError(f"cannot write {path}: it is a file, not a folder")
        d = p
    else:
        if p.is_dir():
            raise InputError(f"cannot write {path}: it is a folder")
        d = p.parent
    d = d if str(d) else Path(".")
    while not d.exists() and d != d.parent:
        d = d.parent
    if not d.is_dir():
        raise InputError(f"cannot write {path}: {d} is a file, not a folder")
    if not os.access(d, os.W_OK | os.X_OK):
        raise InputError(f"cannot write {path}: folder {d} is not writable")
    try:
        fd, probe = tempfile.mkstemp(prefix=".cutkit-probe.", dir=d)
    except OSError as exc:
        raise InputError(f"cannot write {path}: folder {d} is not writable ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)


#: What each command writes into its output folder: the only entries ``--overwrite`` removes.
FOLDER_OUTPUTS: dict[str, tuple[str, ...]] = {
    "simulate": ("frames", "surface", "pictures", "cut.pvd", "cut_surface.pvd", "forces.csv", "summary.json",
                 "model.h5", "cut.mp4", "cut.gif"),
    "cut": ("frames", "cut.pvd", "model.h5"),
    "relax": ("frames", "relax.pvd"),
    "live": ("trajectory.csv", "forces.csv", "summary.json", "model.h5"),
    "sweep": ("results.parquet", "results.csv", "runs"),
}
#: The demo's folder: a simulate folder and the knee model the demo builds (kept and reused).
DEMO_MODEL = ("knee.h5", "knee.h5.key")
FOLDER_OUTPUTS["demo"] = FOLDER_OUTPUTS["simulate"] + DEMO_MODEL


def check_output_folder(path: str | os.PathLike, command: str, overwrite: bool = False,
                        inputs: tuple = ()) -> list[Path]:
    """Check an output folder before any work; return what ``overwrite`` will remove.

    A folder that does not exist or is empty is fine.  A non-empty one is
    refused (an earlier run's files would mix with this run's) unless
    ``overwrite``: then the entries of :data:`FOLDER_OUTPUTS` for ``command``
    are returned, to be removed by :func:`clear_outputs` once the inputs are
    checked; anything else in the folder is left alone.  Nothing is changed here.

    Raises
    ------
    InputError
        The folder cannot be written, is not empty (without ``overwrite``), or
        holds one of ``inputs`` among the outputs ``overwrite`` would remove.
    """
    check_writable(path, folder=True)
    p = Path(path)
    if not p.is_dir():
        return []
    entries = sorted(e.name for e in p.iterdir())
    if not entries:
        return []
    if not overwrite:
        shown = ", ".join(entries[:3]) + (f" (+{len(entries) - 3} more)" if len(entries) > 3 else "")
        resume = "--resume to continue the earlier sweep there, " if command == "sweep" else ""
        raise InputError(f"{path}: the output folder is not empty ({shown}); give {resume}--overwrite to "
                         f"replace the outputs of an earlier `cutkit {command}` there, or another folder")
    ours = [p / name for name in FOLDER_OUTPUTS[command] if (p / name).exists() or (p / name).is_symlink()]
    for inp in inputs:
        if inp is None:
            continue
        q = Path(inp).resolve()
        for o in ours:
            r = o.resolve()
            if q == r or r in q.parents:
                raise InputError(f"{inp}: an input of this run is one of the outputs --overwrite would "
                                 f"replace in {path}; move it or write to another folder")
    return ours


def clear_outputs(paths: list[Path]) -> None:
    """Remove the files and folders :func:`check_output_folder` returned (an earlier run's outputs)."""
    import shutil

    for q in paths:
        try:
            if q.is_dir() and not q.is_symlink():
                shutil.rmtree(q)
            else:
                q.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise InputError(f"cannot remove {q}: {exc.strerror or exc}") from None
