"""Find a libLLVM that Dr.Jit's LLVM back-end accepts (major version >= 16).

Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` when it is first imported. Debian bookworm's default libLLVM-15 makes it
abort, so :func:`configure_llvm` looks for a newer one in the usual library folders and points Dr.Jit at it,
unless the user has already set the variable. It must run before ``drjit`` or ``mitsuba`` is imported; the
package's ``__init__`` does that, so ``import lftransfer`` works from any shell.
"""

from __future__ import annotations

import glob
import os
import re

MIN_LLVM_MAJOR = 16
_SEARCH_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)
_VERSION = re.compile(r"libLLVM(?:[.-]so)?[.-]?(\d+)")


def find_llvm(min_major: int = MIN_LLVM_MAJOR) -> str | None:
    """Return the path of the newest libLLVM with major version >= ``min_major``, or None.

    Args:
        min_major: smallest acceptable major version.

    Returns:
        Absolute path of a shared library, or None when none is installed.
    """
    best: tuple[int, str] | None = None
    for d in _SEARCH_DIRS:
        for path in glob.glob(os.path.join(d, "libLLVM*.so*")) + glob.glob(os.path.join(d, "libLLVM*.dylib")):
            m = _VERSION.search(os.path.basename(path))
            if not m:
                continue
            major = int(m.group(1))
            if major >= min_major and (best is None or major > best[0]):
                best = (major, os.path.realpath(path))
    return None if best is None else best[1]


def configure_llvm() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` to a suitable libLLVM if it is not set already; return the path used."""
    current = os.environ.get("DRJIT_LIBLLVM_PATH")
    if current:
        return current
    path = find_llvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path
