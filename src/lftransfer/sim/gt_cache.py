"""The ground-truth cache: path-traced renders stored under a hash of their inputs, each entry checked on read.

An entry is two files in :func:`cache_dir`: ``<key>.exr`` (the stacked renders) and ``<key>.json``, written
after the image, with the SHA-256 of the inputs (the whole hash; ``key`` is its first 20 characters), the
SHA-256 of the image file's bytes and the stack's shape. Reading an entry verifies all three and that the image
decodes; an entry that fails (truncated, corrupt, swapped for another, written by a run that stopped before its
checksum) is reported as :class:`CacheProblem` so that the caller renders it again and overwrites it.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lftransfer.imageio_utils import read_exr, write_exr, write_text

__all__ = ["CacheProblem", "cache_dir", "entry_paths", "file_sha256", "read_entry", "write_entry"]

FORMAT = "lftransfer-gt-cache/1"


def cache_dir() -> Path:
    """Folder of cached ground-truth renders: ``$LFT_CACHE_DIR/ground_truth`` or
    ``~/.cache/lftransfer/ground_truth``."""
    return Path(os.environ.get("LFT_CACHE_DIR", Path.home() / ".cache" / "lftransfer")) / "ground_truth"


def entry_paths(inputs_sha256: str) -> tuple[Path, Path]:
    """(image, checksum file) of the entry for these inputs."""
    key = inputs_sha256[:20]
    return cache_dir() / f"{key}.exr", cache_dir() / f"{key}.json"


@dataclass(frozen=True)
class CacheProblem:
    """Why a cache entry cannot be used.

    Attributes:
        path: the entry's image file (or folder).
        reason: what is wrong, e.g. ``"its checksum does not match (corrupt or replaced)"``.
        what: which cache (the calibration cache, :mod:`lftransfer.runs.calibration_cache`, says its own).
        action: what is done instead.
    """

    path: Path
    reason: str
    what: str = "ground-truth cache entry"
    action: str = "rendering it again"

    def message(self) -> str:
        """One line for the terminal and the report."""
        return f"{self.what} {self.path} {self.reason}; {self.action}"


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_entry(inputs_sha256: str, shape: tuple[int, int, int]) -> np.ndarray | CacheProblem | None:
    """The cached stack for these inputs, verified.

    Args:
        inputs_sha256: SHA-256 (hex) of everything the renders depend on.
        shape: (H, W, C) the stack must have.

    Returns:
        (H, W, C) float32 stack; None when there is no entry; a :class:`CacheProblem` when the entry is bad.
    """
    image, meta_path = entry_paths(inputs_sha256)
    if not image.exists():
        return None
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return CacheProblem(image, "has no checksum file (written by an older version or by a run that stopped)")
    except (OSError, ValueError) as exc:
        return CacheProblem(image, f"has an unreadable checksum file {meta_path.name} ({exc})")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        return CacheProblem(image, f"has a checksum file {meta_path.name} of another format")
    if meta.get("inputs_sha256") != inputs_sha256:
        return CacheProblem(image, "belongs to other inputs (swapped or copied from another entry)")
    try:
        actual = file_sha256(image)
    except OSError as exc:
        return CacheProblem(image, f"cannot be read ({exc.strerror or exc})")
    if meta.get("sha256") != actual:
        return CacheProblem(image, "does not match its checksum (corrupt, truncated or replaced)")
    try:
        stack = read_exr(image)
    except Exception as exc:  # noqa: BLE001 - any decoder failure is a bad entry
        return CacheProblem(image, f"cannot be decoded ({type(exc).__name__}: {exc})")
    if tuple(stack.shape) != tuple(shape):
        return CacheProblem(image, f"holds a {tuple(stack.shape)} stack, expected {tuple(shape)}")
    return stack


def write_entry(inputs_sha256: str, stack: np.ndarray) -> Path:
    """Store a stack for these inputs: the image, then its checksum file (both atomically).

    Returns:
        The image file.
    """
    image, meta_path = entry_paths(inputs_sha256)
    meta_path.unlink(missing_ok=True)                  # never a checksum beside an image it does not describe
    write_exr(image, stack)
    write_text(meta_path, json.dumps({"format": FORMAT, "inputs_sha256": inputs_sha256, "sha256": file_sha256(image),
                                      "shape": list(stack.shape)}, indent=1) + "\n")
    return image
