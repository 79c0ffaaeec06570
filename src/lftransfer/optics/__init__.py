"""Optics of the interface: the lens array lattice and the lenslet pixel <-> ray maps of the devices behind it."""

from lftransfer.optics.device import LensletDevice
from lftransfer.optics.lens_array import LensArray

__all__ = ["LensArray", "LensletDevice"]
