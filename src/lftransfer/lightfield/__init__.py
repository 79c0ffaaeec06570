"""Light fields on the interface and the codecs between them and the device images behind the array."""

from lftransfer.lightfield.codec import LensletCodec
from lftransfer.lightfield.devices import CameraModel, LightFieldDecoder, LightFieldEncoder, ProjectorModel
from lftransfer.lightfield.lightfield import LightField
from lftransfer.lightfield.response import ResponseCurve

__all__ = [
    "CameraModel",
    "LensletCodec",
    "LightField",
    "LightFieldDecoder",
    "LightFieldEncoder",
    "ProjectorModel",
    "ResponseCurve",
]
