"""Typed requests and answers that cross the rig boundary (docs/architecture.md, "The rig boundary").

A :class:`~lftransfer.rig.base.Rig` is driven by four kinds of action: arrange what stands in front of (or
behind) the lens array (:data:`Setup`), show a projector image, capture the LF camera (:class:`LFCapture` ->
:class:`LFFrame`) and capture the view camera (:class:`ViewCapture` -> :class:`ViewFrame`). Every request is a
frozen dataclass of plain values, so a physical back-end can implement them one by one (a set-up becomes an
operator prompt), a recording can store them (:meth:`to_json`) and a replay can look them up
(:func:`request_key`).

Coordinates: metres in the *rig frame*, the frame the rig file describes: the lens array's nominal plane is
z = 0 with the real side at z > 0, centred on the nominal array's centre (the scene file's world). A request for
a place ("hold the board about 8 cm in front of the array") is what the pipeline asks for; where the board
really ends up is for the calibration to measure.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import json
from dataclasses import dataclass, field
from typing import Union

import numpy as np

__all__ = ["SCREEN_TRANSMISSION", "Board", "CleanPlate", "Collimator", "FocalPlaneDiffuser", "LFCapture", "LFFrame",
           "MirrorBall", "RealScene", "RigInfo", "Setup", "SETUPS", "ViewCapture", "ViewFrame", "WhiteField",
           "describe", "image_digest", "request_key", "setup_from_json"]


def _vec3(value, name: str) -> tuple[float, float, float]:
    v = tuple(float(x) for x in np.asarray(value, np.float64).ravel())
    if len(v) != 3 or not all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


#: A translucent calibration board (a rear-projection screen, :class:`Board`'s ``translucent``) passes this share of
#: the light it scatters to its other side and reflects the rest, both diffusely (nominal, the screen's datasheet).
SCREEN_TRANSMISSION = 0.5


# -- set-ups: what the rig shows the array -------------------------------------------------------------------

@dataclass(frozen=True)
class RealScene:
    """The real scene as the run uses it: real objects in place, the point light on, the room dark.

    This is the state a rig starts in and the one the transfer needs.

    Attributes:
        time_s: the moment of an animated scene, seconds from its start. The simulated rig poses its real objects
            at this time (their keyframes); on a physical rig the real objects move by themselves and it only
            labels the frame.
    """

    time_s: float = 0.0
    kind: str = field(default="real_scene", init=False)

    def __post_init__(self) -> None:
        t = self.time_s
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or t < 0:
            raise ValueError(f"RealScene.time_s must be a finite number of seconds >= 0, got {t!r}")
        object.__setattr__(self, "time_s", float(t))

    def prompt(self) -> str:
        return "Put the real objects in place and switch the point light on; take every calibration target away."


@dataclass(frozen=True)
class Collimator:
    """A collimated source (a point source at infinity) shining into the array from the real side.

    Attributes:
        direction: (3,) direction the beam comes from, rig frame, z > 0 (on-axis: (0, 0, 1)); the collimator's
            tilt is set on its mount.
    """

    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    kind: str = field(default="collimator", init=False)

    def __post_init__(self) -> None:
        d = _vec3(self.direction, "Collimator.direction")
        if not d[2] > 0:
            raise ValueError(f"Collimator.direction must point to the real side (z > 0), got {d}")
        n = float(np.linalg.norm(d))
        if abs(n - 1.0) > 1e-12:              # normalise once: a described set-up rebuilds to the same values
            d = tuple(x / n for x in d)
        object.__setattr__(self, "direction", d)

    def prompt(self) -> str:
        tx, ty = self.direction[0] / self.direction[2], self.direction[1] / self.direction[2]
        return (f"Switch the collimator on in front of the array, tilted to tan = ({tx:+.3f}, {ty:+.3f}) on its "
                "mount; point light off, projector unused.")


@dataclass(frozen=True)
class WhiteField:
    """A white diffuser directly in front of the array, lit evenly from the real side (a 'white image')."""

    kind: str = field(default="white_field", init=False)

    def prompt(self) -> str:
        return "Put the white diffuser against the array's real side and light it evenly; point light off."


@dataclass(frozen=True)
class FocalPlaneDiffuser:
    """A diffuser at the lenslets' focal plane (behind the array): the LF camera sees the projector's pixels.

    Attributes:
        transmission: fraction of the projector's light the diffuser passes towards the camera (nominal).
    """

    transmission: float = 0.5
    kind: str = field(default="focal_plane_diffuser", init=False)

    def prompt(self) -> str:
        return "Slide the diffuser into the lenslets' focal plane (behind the array); room dark."


@dataclass(frozen=True)
class Board:
    """A flat diffuse board held in front of the array, real objects away, point light off (or on).

    Attributes:
        centre: (3,) where the board's centre is asked for, rig frame, metres (z > 0).
        normal: (3,) unit normal, towards the side the board is seen and lit from.
        size: (width, height) metres.
        albedo: diffuse reflectance of the board (a grey target).
        chart: (columns, rows, square metres) of a chessboard printed on the board's centre (dark squares of
            reflectance albedo / 4), or None for a plain board.
        point_light: the real point light on (the board lit by it and by whatever the projector shows; the point
            light step of the calibration keeps the projector black); off by default. :func:`describe` leaves it
            out while it is off, so recordings made before it existed replay unchanged.
        light: with ``point_light``, which of the scene's point lights is on (0-based, in the scene file's order;
            the others off), or None: all of them. :func:`describe` leaves it out while it is None.
        translucent: a rear-projection screen (the chessboard printed into it) instead of an opaque board: what the
            array draws on the side facing it (``normal``) is seen from the other side too, by a view camera in
            front of the board. :func:`describe` leaves it out while it is False.
    """

    centre: tuple[float, float, float]
    normal: tuple[float, float, float]
    size: tuple[float, float] = (0.3, 0.3)
    albedo: float = 0.8
    chart: tuple[int, int, float] | None = None
    point_light: bool = False
    light: int | None = None
    translucent: bool = False
    kind: str = field(default="board", init=False)

    def __post_init__(self) -> None:
        c, n = _vec3(self.centre, "Board.centre"), _vec3(self.normal, "Board.normal")
        if not c[2] > 0:
            raise ValueError(f"Board.centre must lie on the real side (z > 0), got {c}")
        norm = float(np.linalg.norm(n))
        if norm == 0:
            raise ValueError("Board.normal must not be zero")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "normal", n if abs(norm - 1.0) <= 1e-12 else tuple(x / norm for x in n))
        object.__setattr__(self, "size", tuple(float(s) for s in self.size))
        if self.chart is not None:
            cols, rows, square = self.chart
            object.__setattr__(self, "chart", (int(cols), int(rows), float(square)))
        if not isinstance(self.point_light, (bool, np.bool_)):
            raise ValueError(f"Board.point_light must be True or False, got {self.point_light!r}")
        object.__setattr__(self, "point_light", bool(self.point_light))
        if not isinstance(self.translucent, (bool, np.bool_)):
            raise ValueError(f"Board.translucent must be True or False, got {self.translucent!r}")
        object.__setattr__(self, "translucent", bool(self.translucent))
        if self.light is not None:
            if isinstance(self.light, (bool, np.bool_)) or not isinstance(self.light, (int, np.integer)) \
                    or self.light < 0:
                raise ValueError(f"Board.light must be None or a light's index >= 0, got {self.light!r}")
            if not self.point_light:
                raise ValueError("Board.light names a point light to switch on, but point_light is False")
            object.__setattr__(self, "light", int(self.light))

    def prompt(self) -> str:
        c = self.centre
        board = "translucent screen" if self.translucent else "board"
        what = f"the {board} with the printed {self.chart[0]} x {self.chart[1]} chessboard" if self.chart else \
            f"the plain grey {board}"
        where = (f"Hold {what} with its centre about {100 * c[2]:.0f} cm in front of the array "
                 f"(x {100 * c[0]:+.0f} cm, y {100 * c[1]:+.0f} cm), facing ({self.normal[0]:+.2f}, "
                 f"{self.normal[1]:+.2f}, {self.normal[2]:+.2f})")
        if self.point_light:
            which = "the point light ON" if self.light is None else \
                f"point light {self.light + 1} (in the scene file's order) ON and every other one off"
            towards = "the point light" if self.light is None else f"point light {self.light + 1}"
            return (f"{where}, towards {towards}; take the real objects away and switch {which} "
                    "(the projector stays black; keep your hand and body out of the light's path).")
        return f"{where}, where the projected image looks sharp; take the real objects away, point light off."


@dataclass(frozen=True)
class MirrorBall:
    """The light probe: a mirror ball on its mount, in the room's own light (projector black, real objects away),
    for the view camera to photograph.

    Attributes:
        centre: (3,) where the mount holds the ball's centre, metres (the scene's world frame, as a board's centre;
            real side, z > 0).
        radius: metres.
    """

    centre: tuple[float, float, float]
    radius: float
    kind: str = field(default="mirror_ball", init=False)

    def __post_init__(self) -> None:
        c = _vec3(self.centre, "MirrorBall.centre")
        if not c[2] > 0:
            raise ValueError(f"MirrorBall.centre must lie on the real side (z > 0), got {c}")
        if not (isinstance(self.radius, (int, float, np.floating)) and np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"MirrorBall.radius must be a positive number of metres, got {self.radius!r}")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "radius", float(self.radius))

    def prompt(self) -> str:
        c = self.centre
        return (f"Put the mirror ball ({200 * self.radius:.1f} cm across) on its mount, centre at x {100 * c[0]:+.1f}, "
                f"y {100 * c[1]:+.1f}, z {100 * c[2]:.1f} cm; take the real objects away, room lights as for the "
                "scene, projector black.")


@dataclass(frozen=True)
class CleanPlate:
    """The clean plate: the rig as the real scene has it (its lights on, the room as it is, projector black) with
    the real objects taken away, for the view camera to photograph what stands behind them (the array). The real
    objects' outline in the view camera is where a photograph of the real scene differs from it
    (:mod:`lftransfer.real_depth.outline`)."""

    kind: str = field(default="clean_plate", init=False)

    def prompt(self) -> str:
        return ("Take the real objects away and leave everything else as it is (point light on, room lights as for "
                "the scene, projector black, nothing in front of the array).")


Setup = Union[RealScene, Collimator, WhiteField, FocalPlaneDiffuser, Board, MirrorBall, CleanPlate]
SETUPS: dict[str, type] = {"real_scene": RealScene, "collimator": Collimator, "white_field": WhiteField,
                           "focal_plane_diffuser": FocalPlaneDiffuser, "board": Board, "mirror_ball": MirrorBall,
                           "clean_plate": CleanPlate}


def setup_from_json(data: dict) -> Setup:
    """The set-up a :func:`describe` dict stands for (for recordings)."""
    data = dict(data)
    kind = data.pop("kind", None)
    if kind not in SETUPS:
        raise ValueError(f"unknown set-up kind {kind!r}; expected one of {sorted(SETUPS)}")
    cls = SETUPS[kind]
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = set(data) - fields
    if unknown:
        raise ValueError(f"set-up {kind!r}: unknown fields {sorted(unknown)}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


# -- captures --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LFCapture:
    """Capture the LF camera.

    Attributes:
        exposure_scale: exposure time relative to the rig's normal one (exposure bracketing), > 0.
        frames: frames averaged (noise); the answer is their mean, rounded to codes.
    """

    exposure_scale: float = 1.0
    frames: int = 1

    def __post_init__(self) -> None:
        if not (np.isfinite(self.exposure_scale) and self.exposure_scale > 0):
            raise ValueError(f"LFCapture.exposure_scale must be a positive number, got {self.exposure_scale!r}")
        if int(self.frames) < 1:
            raise ValueError(f"LFCapture.frames must be >= 1, got {self.frames!r}")
        object.__setattr__(self, "exposure_scale", float(self.exposure_scale))
        object.__setattr__(self, "frames", int(self.frames))


@dataclass(frozen=True)
class ViewCapture:
    """Capture the view camera.

    Attributes:
        frames: frames averaged.
        quality: samples per pixel a simulated view camera takes (None: its default); a physical camera takes
            it as a hint for how many frames to average at least.
    """

    frames: int = 1
    quality: int | None = None

    def __post_init__(self) -> None:
        if int(self.frames) < 1:
            raise ValueError(f"ViewCapture.frames must be >= 1, got {self.frames!r}")
        if self.quality is not None and int(self.quality) < 1:
            raise ValueError(f"ViewCapture.quality must be >= 1 or None, got {self.quality!r}")
        object.__setattr__(self, "frames", int(self.frames))


@dataclass(frozen=True)
class LFFrame:
    """An LF camera image.

    Attributes:
        codes: (H, W, 3) uint16 camera codes of ``bits`` bits (device integers, before any linearisation).
        bits: bit depth of the codes.
        exposure_scale: the exposure it was taken at, relative to the normal one.
    """

    codes: np.ndarray
    bits: int
    exposure_scale: float = 1.0


@dataclass(frozen=True)
class ViewFrame:
    """A view camera image.

    Attributes:
        radiance: (H, W, 3) float32 linear radiance, W m^-2 sr^-1 (the view camera is the rig's radiometric
            reference: a physical back-end linearises its codes with the view camera's response and scale
            from the rig file).
    """

    radiance: np.ndarray


@dataclass(frozen=True)
class RigInfo:
    """What a rig's devices are.

    Attributes:
        lf_camera: (width, height) of the LF camera, pixels.
        lf_camera_bits: bit depth of its codes.
        projector: (width, height) of the projector, pixels.
        projector_bits: bit depth of its codes (8: uint8 images, else uint16).
        view: (width, height) of the view camera.
        kind: "sim", "hardware", "replay", ...
    """

    lf_camera: tuple[int, int]
    lf_camera_bits: int
    projector: tuple[int, int]
    projector_bits: int
    view: tuple[int, int]
    kind: str = "unknown"

    @property
    def projector_shape(self) -> tuple[int, int]:
        """(height, width) of a projector image."""
        return (self.projector[1], self.projector[0])

    @property
    def projector_dtype(self) -> type:
        return np.uint8 if self.projector_bits <= 8 else np.uint16

    def black(self) -> np.ndarray:
        """(H, W, 3) all-zero projector image."""
        return np.zeros((*self.projector_shape, 3), self.projector_dtype)

    def check_projector_image(self, image: np.ndarray) -> np.ndarray:
        """``image`` as the projector takes it, or a ValueError naming what is wrong."""
        image = np.asarray(image)
        expected = (*self.projector_shape, 3)
        if image.shape != expected or image.dtype != self.projector_dtype:
            raise ValueError(f"projector image must be {expected} {np.dtype(self.projector_dtype).name}, "
                             f"got {image.shape} {image.dtype}")
        return image


# -- describing and keying requests ----------------------------------------------------------------------------

def describe(request) -> dict:
    """A request (set-up or capture) as plain JSON data."""
    data = dataclasses.asdict(request)
    if isinstance(request, Board) and not request.point_light:
        del data["point_light"]           # as before the field existed: older recordings keep their keys
    if isinstance(request, Board) and request.light is None:
        del data["light"]
    if isinstance(request, Board) and not request.translucent:
        del data["translucent"]
    if isinstance(request, LFCapture):
        data["kind"] = "lf_capture"
    elif isinstance(request, ViewCapture):
        data["kind"] = "view_capture"
    return json.loads(json.dumps(data))


def image_digest(image: np.ndarray) -> str:
    """SHA-256 of an image's shape, dtype and bytes (hex): identifies a projector image."""
    a = np.ascontiguousarray(image)
    h = hashlib.sha256(f"{a.shape}|{a.dtype.str}|".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def request_key(setup: Setup, projected: str | None, request) -> str:
    """Key of a capture in a recording: the set-up, the projector image's digest and the capture request."""
    return json.dumps({"setup": describe(setup), "projected": projected, "capture": describe(request)},
                      sort_keys=True)
