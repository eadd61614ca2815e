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
