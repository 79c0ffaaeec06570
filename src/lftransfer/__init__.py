"""lftransfer: light field transfer between real and synthetic objects.

Importing the package points Dr.Jit at a suitable libLLVM (see :mod:`lftransfer._llvm`).
"""

from lftransfer._llvm import configure_llvm as _configure_llvm

_configure_llvm()

__version__ = "0.1.0"
