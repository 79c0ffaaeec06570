"""What the rig measures of the real scene itself, beside the rig's calibration: its depth as the view camera sees
it (docs/architecture.md, "Occlusion"), from the LF camera's depth carried into the view (:mod:`.lightfield`), from
the projector and the view camera as a structured-light pair (:mod:`.structured_light`), and the better of the two
per pixel (:mod:`.fusion`); the real surface those depths measure, with normals and a confidence per point
(:mod:`.surface`); and the room's light from a mirror ball, the light probe (:mod:`.probe`)."""

from lftransfer.real_depth.fusion import fuse_depths
from lftransfer.real_depth.lightfield import (ViewDepth, lightfield_points, splat_depth,
                                              view_depth_from_lightfield)
from lftransfer.real_depth.structured_light import decode_structured_light, measure_structured_light

__all__ = ["ViewDepth", "decode_structured_light", "fuse_depths", "lightfield_points", "measure_structured_light",
           "splat_depth", "view_depth_from_lightfield"]
