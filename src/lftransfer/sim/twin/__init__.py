"""The device twin: the simulated world in its own process, behind the interfaces a physical rig has.

``lft twin serve SCENE.toml --rig-file twin.toml`` runs :class:`~.serve.Twin`: it reads what the projector window
really shows on an X display, renders the LF camera and the view camera with the simulated rig's physics, streams
them over HTTP to OpenCV's ``VideoCapture`` with the latency, jitter, dropped frames and stops that real devices
have, and answers the hardware rig's operator requests (boards placed with a hidden hand error). The hardware
back-end (``--rig hardware:twin.toml``) then runs its whole path on our machines; ``lft twin score RUN_DIR``
(:mod:`.score`) scores a run against the ground truth the twin's manifest names.
"""

from lftransfer.sim.twin.cameras import CameraTiming
from lftransfer.sim.twin.serve import Twin, TwinOptions, manifest_path

__all__ = ["CameraTiming", "Twin", "TwinOptions", "manifest_path"]
