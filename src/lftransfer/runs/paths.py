"""Output paths checked before any work: a folder that is a file, a file name that is a folder, a folder that
cannot be written, an unwritable ground-truth cache.

Each check writes nothing that stays: it probes the folder that will receive the files (or the nearest folder
that exists above it) with a temporary file, removed at once, so it answers what the run would meet.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["OutputPathError", "check_cache_dir", "check_output_dir", "check_output_file"]


class OutputPathError(ValueError):
    """An output path that cannot receive the run's files; the message names the option, the path and what is
    wrong, e.g. ``--out out/run: is a file, expected a folder``."""


def _nearest_existing(path: Path) -> Path:
    """``path`` or the nearest of its parents that exists."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _probe(folder: Path) -> str | None:
    """Why no file can be created in ``folder``, or None when one can."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".lft-probe-", dir=folder)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.unlink(tmp)
    return None


def _check_folder(path: Path, label: str, own: bool = True) -> None:
    """``path`` is or can become a folder that takes files.

    Args:
        path: the folder.
        label: what messages start with (the option and the path it names).
        own: ``path`` is what the option names (else it is the folder of a file the option names).
    """
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{label}: is a file, expected a folder" if own else f"{label}: {path} is a file")
    base = _nearest_existing(path)
    if not base.is_dir():
        raise OutputPathError(f"{label}: {base} is a file, so the folder cannot be made")
    why = _probe(base)
    if why is not None:
        where = "" if base == Path(os.path.abspath(path)) else f" (in {base}, where it would be made)"
        raise OutputPathError(f"{label}: cannot write there{where}: {why}")


def check_output_dir(path: str | Path, option: str = "--out") -> Path:
    """Check an output folder before the work starts.

    Args:
        path: the folder (it need not exist; it is not made here).
        option: the command-line option that named it, for the message.

    Returns:
        The path.

    Raises:
        OutputPathError: the path is a file, lies below a file, or its folder cannot be written.
    """
    path = Path(path)
    _check_folder(path, f"{option} {path}")
    return path


def check_output_file(path: str | Path, option: str = "--out", example: str | None = None) -> Path:
    """Check an output file's name before the work starts.

    Args:
        path: the file to write (it may exist: it is replaced).
        option: the command-line option that named it, for the message.
        example: a file name to suggest when ``path`` is a folder (e.g. ``"calibration.json"``).

    Returns:
        The path.

    Raises:
        OutputPathError: the path is a folder, or its folder is a file or cannot be written.
    """
    path = Path(path)
    if path.is_dir():
        hint = f" (e.g. {option} {path / example})" if example else ""
        raise OutputPathError(f"{option} {path}: is a folder, expected a file name{hint}")
    _check_folder(path.parent, f"{option} {path}", own=False)
    return path


def check_cache_dir(path: str | Path) -> Path:
    """Check the ground-truth cache folder before the work starts.

    Raises:
        OutputPathError: the folder cannot be made or written; the message says how to choose another.
    """
    path = Path(path)
    try:
        _check_folder(path, f"ground-truth cache {path}")
    except OutputPathError as exc:
        raise OutputPathError(f"{exc} (set LFT_CACHE_DIR to a writable folder, or pass --no-cache)") from None
    return path
