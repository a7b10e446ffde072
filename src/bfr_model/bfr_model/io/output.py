"""Outputs written whole or not at all, and never over an existing one without force.

Every command that writes a file or a folder goes through this module:

- :func:`check_new` refuses an existing target unless ``force`` (one line: what exists and
  how to replace it), before any work is done;
- :func:`atomic_file` and :func:`atomic_dir` yield a temporary path beside the target (same
  file system) and move it into place with one ``rename`` when the block succeeds; on any
  failure the temporary is removed and the target is untouched. A folder replaced with
  ``force`` is first renamed away, then the new one renamed in, then the old one removed,
  so a reader sees the old or the new folder, never a mixture.

Pure Python; no ``rclpy``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["OutputError", "atomic_dir", "atomic_file", "check_new", "write_text"]


class OutputError(ValueError):
    """An output cannot be written (exists without force, parent missing); one line."""


def check_new(path: str | Path, force: bool) -> Path:
    """The target ``path``, checked: refused when it exists and ``force`` is not given.

    Raises
    ------
    OutputError
        The target exists (and not ``force``), or its folder does not exist.
    """
    p = Path(path)
    if (p.exists() or p.is_symlink()) and not force:
        kind = "folder" if p.is_dir() else "file"
        raise OutputError(f"{p}: {kind} exists already (--force replaces it)")
    if not p.resolve().parent.is_dir():
        raise OutputError(f"{p}: folder {p.resolve().parent} does not exist")
    return p


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_file(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary file path; rename it to ``path`` when the block succeeds.

    The temporary is ``.<name>.partial-<pid><suffix>`` beside the target (so writers that
    choose their format by suffix still do).

    Raises
    ------
    OutputError
        See :func:`check_new`.
    """
    p = check_new(path, force)
    fd, name = tempfile.mkstemp(prefix=f".{p.stem}.partial-{os.getpid()}-", suffix=p.suffix,
                                dir=p.resolve().parent)
    os.close(fd)
    tmp = Path(name)
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        yield tmp
        if p.is_dir() and not p.is_symlink():
            raise OutputError(f"{p}: a folder is in the way of the file")
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_dir(path: str | Path, force: bool = False, *, create: bool = True) -> Iterator[Path]:
    """Yield a temporary folder path; rename it to ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or Path
        The folder to write.
    force : bool
        Replace an existing ``path`` (file or folder).
    create : bool
        Create the temporary folder (False: yield a free path for a writer that creates
        the folder itself, e.g. a bag writer).

    Raises
    ------
    OutputError
        See :func:`check_new`.
    """
    p = check_new(path, force)
    parent = p.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.partial-{os.getpid()}-", dir=parent))
    os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes it private; the result is ordinary
    if not create:
        tmp.rmdir()
    try:
        yield tmp
        if p.exists() or p.is_symlink():
            old = Path(tempfile.mkdtemp(prefix=f".{p.name}.old-", dir=parent))
            old.rmdir()
            p.rename(old)
            tmp.rename(p)
            if old.is_dir() and not old.is_symlink():
                shutil.rmtree(old, ignore_errors=True)
            else:
                old.unlink(missing_ok=True)
        else:
            tmp.rename(p)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_text(path: str | Path, text: str, force: bool = False) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_file`); returns the path."""
    with atomic_file(path, force) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
