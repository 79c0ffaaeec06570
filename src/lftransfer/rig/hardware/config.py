"""The rig file of a physical rig: which devices the :class:`~lftransfer.rig.hardware.HardwareRig` opens.

A TOML file with three tables, validated with pydantic (``example_rig.toml`` beside this module documents every
field)::

    [lf_camera]     source, width, height, bits, exposure, gain, frames, timeout_s, ...
    [view_camera]   the same, plus response_gamma and radiance_scale (its radiometric linearisation); left out
                    only in the rig file of a scene's second or later light field interface
    [projector]     display, x_display, width, height, bits, settle_s, drop_frames, stale_check, timeout_s
    [operator]      kind (terminal | http | command), url, command, timeout_s  (optional: who arranges set-ups)

An invalid file raises :class:`RigFileError` with one line naming the file, the field path and what was
expected, e.g. ``rig.toml: lf_camera.bits: Input should be less than or equal to 16, found 20``.

:func:`write_rig_value` writes one value back (the latency calibration writes ``projector.settle_s``) by a
careful line edit that keeps every other line, comments included; the result is parsed again and must equal the
old contents with that one value changed. Only where the line edit cannot do it (the table written inline or as
dotted keys) is the whole file rewritten with ``tomli_w`` (comments lost, a warning logged). Files are replaced
atomically (:func:`lftransfer.imageio_utils.write_text`).
"""

from __future__ import annotations

import copy
import logging
import math
import numbers
import os
import re
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from lftransfer.imageio_utils import write_text
from lftransfer.rig.requests import RigInfo
from lftransfer.validation import STRICT_NUMBER, read_toml, validation_message

__all__ = ["CameraConfig", "HardwareRigConfig", "OperatorConfig", "ProjectorConfig", "RigFileError", "ViewCameraConfig",
           "load_rig_file", "parse_rig_file", "write_rig_value"]

_log = logging.getLogger(__name__)


class RigFileError(ValueError):
    """An invalid or unwritable rig file.

    The message reads ``"<file>: <field path>: <what was expected, what was found>"``.
    """


# -- field types -----------------------------------------------------------------------------------------------

_Num = STRICT_NUMBER
PosFloat = Annotated[float, _Num, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, _Num, Field(ge=0, allow_inf_nan=False)]
PosInt = Annotated[int, _Num, Field(gt=0)]
NonNegInt = Annotated[int, _Num, Field(ge=0)]


def _source_type(value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise ValueError("expected a device index (an integer) or a string (a /dev/video path, a video file, an "
                         f"image-sequence pattern or genicam:SERIAL), found {type(value).__name__} {value!r}")
    return value


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


SourceKind = Literal["index", "v4l2", "video", "images", "genicam", "stream"]

STREAM_SCHEMES = ("http://", "https://", "tcp://", "udp://", "rtsp://", "rtp://", "srt://")
"""URL schemes of network cameras, opened by OpenCV's FFmpeg back-end."""


class CameraConfig(_Model):
    """A camera of the rig.

    Attributes:
        source: what to open: an integer device index (``0``), a V4L2 device path (``"/dev/video2"``), a video
            file (``"run.avi"``), an image-sequence pattern (``"frames/%04d.png"``), ``"genicam:SERIAL"``
            (a GenICam camera through ``harvesters``, with ``cti``), or the URL of a network camera's stream
            (``"http://10.0.0.5:8600/lf"``, ``tcp://``, ``rtsp://``: IP and streaming cameras, and the device
            twin's cameras). Relative file paths are relative to the rig file's folder (the loader makes them
            absolute).
        cti: GenTL producer (``.cti`` file) for a ``genicam:`` source; required there, unused otherwise.
        width, height: image size the camera must deliver, pixels.
        bits: bit depth of the codes the camera returns; captures are uint16 codes of this many bits.
            An 8-bit frame is scaled to full scale of ``bits`` (code * (2^bits - 1) / 255); a 16-bit frame
            holds ``bits``-bit codes in its low bits (GenICam ``Mono12``) or, with ``msb_aligned``, in its high
            bits (V4L2 ``Y16``).
        msb_aligned: 16-bit frames hold their codes in the high bits (shifted down by 16 - bits).
        exposure: exposure set at opening, in the driver's units (OpenCV ``CAP_PROP_EXPOSURE``: V4L2 uses
            100 us units; GenICam ``ExposureTime`` is microseconds), or None to leave the camera's own.
            Exposure bracketing scales it, so the units must be proportional to the exposure time.
        gain: gain set at opening (``CAP_PROP_GAIN`` / GenICam ``Gain``), or None.
        frames: frames averaged per capture at least (a request asking for more gets more).
        timeout_s: longest wait for one frame (and for opening the device), seconds.
        planar: the camera delivers its colour frames as one monochrome image of three planes, R above G above
            B ((3 H, W)); a stream camera whose bits do not fit a colour format that OpenCV's FFmpeg reader
            returns at full depth (it returns 16 bits only as GRAY16LE) sends them so.
        control: URL of the camera's control API (HTTP, JSON ``{"exposure": value}`` read by GET and set by
            POST, as IP cameras offer), for a stream camera whose exposure is set over the network; None: none.
        timestamps: what dates a stream camera's frame: ``"arrival"``, when the reader got it; ``"stream"``, the
            frame's own timestamp in the stream (its presentation time, as a camera that stamps its frames at
            exposure sends it), carried to this machine's clock by the smallest arrival delay seen. ``"stream"``
            keeps a frame that waited in a buffer or behind a busy reader from passing as fresh; it needs a
            camera whose stream timestamps are its capture times (the device twin's are), not a frame counter.
    """

    source: Annotated[Union[int, str], BeforeValidator(_source_type)]
    cti: Path | None = None
    width: PosInt
    height: PosInt
    bits: Annotated[int, _Num, Field(ge=1, le=16)] = 8
    msb_aligned: bool = False
    exposure: PosFloat | None = None
    gain: NonNegFloat | None = None
    frames: PosInt = 1
    timeout_s: PosFloat = 5.0
    planar: bool = False
    control: str | None = None
    timestamps: Literal["arrival", "stream"] = "arrival"

    @field_validator("control")
    @classmethod
    def _control(cls, value: str | None) -> str | None:
        if value is not None and not value.startswith(("http://", "https://")):
            raise ValueError(f"expected the camera's control URL (http://...), found {value!r}")
        return value

    @field_validator("source")
    @classmethod
    def _source(cls, value: int | str, info: ValidationInfo) -> int | str:
        if isinstance(value, int):
            if value < 0:
                raise ValueError(f"a device index must be >= 0, found {value}")
            return value
        value = value.strip()
        if not value:
            raise ValueError("expected a device index, a /dev/video path, a video file, an image-sequence "
                             "pattern or genicam:SERIAL, found an empty string")
        if value.lower().startswith("genicam:"):
            if not value.split(":", 1)[1].strip():
                raise ValueError(f"genicam: needs the camera's serial number (genicam:SERIAL), found {value!r}")
            return value
        if value.startswith("/dev/") or value.lower().startswith(STREAM_SCHEMES):
            return value
        base = (info.context or {}).get("base_dir")
        if base is not None and not Path(value).is_absolute():
            value = str(Path(base) / value)
        return value

    @field_validator("cti")
    @classmethod
    def _cti(cls, value: Path | None, info: ValidationInfo) -> Path | None:
        base = (info.context or {}).get("base_dir")
        if value is not None and base is not None and not value.is_absolute():
            value = Path(base) / value
        return value

    @model_validator(mode="after")
    def _genicam_needs_cti(self) -> "CameraConfig":
        if self.kind == "genicam" and self.cti is None:
            raise ValueError("a genicam: source needs cti = the GenTL producer (.cti file) of the camera's "
                             "vendor")
        if self.timestamps == "stream" and self.kind != "stream":
            raise ValueError(f"timestamps = \"stream\" needs a stream URL source (http://, tcp://, rtsp://, ...), "
                             f"found source {self.source!r}")
        return self

    @property
    def kind(self) -> SourceKind:
        """``"index"``, ``"v4l2"``, ``"video"``, ``"images"`` or ``"genicam"``: how the source is opened."""
        s = self.source
        if isinstance(s, int):
            return "index"
        if s.lower().startswith("genicam:"):
            return "genicam"
        if s.startswith("/dev/"):
            return "v4l2"
        if s.lower().startswith(STREAM_SCHEMES):
            return "stream"
        if re.search(r"%0?\d*d", s):
            return "images"
        return "video"

    @property
    def live(self) -> bool:
        """A camera (True) rather than a recording (a video file or an image sequence, False)."""
        return self.kind in ("index", "v4l2", "genicam", "stream")

    @property
    def levels(self) -> int:
        """Largest code, 2^bits - 1."""
        return (1 << self.bits) - 1

    @property
    def serial(self) -> str | None:
        """The serial number of a ``genicam:`` source, else None."""
        return self.source.split(":", 1)[1].strip() if self.kind == "genicam" else None  # type: ignore[union-attr]


class ViewCameraConfig(CameraConfig):
    """The view camera: a :class:`CameraConfig` plus its radiometric linearisation.

    Attributes:
        response_gamma: codes -> linear signal: (code / (2^bits - 1)) ^ gamma; one number or one per channel
            (R, G, B). 2.2 suits an 8-bit webcam's sRGB-like output; 1.0 a linear (raw) camera.
        radiance_scale: linear signal 1.0 -> radiance, W m^-2 sr^-1 (from a radiometric calibration at the
            exposure and gain set here).
    """

    response_gamma: Union[PosFloat, Annotated[list[PosFloat], Field(min_length=3, max_length=3)]] = 2.2
    radiance_scale: PosFloat = 1.0

    @property
    def gamma_rgb(self) -> tuple[float, float, float]:
        """The response gamma per channel."""
        g = self.response_gamma
        return (float(g),) * 3 if isinstance(g, (int, float)) else tuple(float(x) for x in g)  # type: ignore


class ProjectorConfig(_Model):
    """The projector, driven as a monitor of the machine.

    Attributes:
        display: which monitor (0 = the primary one, in the window system's order).
        x_display: the X display the window opens on (``":1"``; the process's ``DISPLAY`` is set to it), or None
            for the session's own ``$DISPLAY``.
        width, height: the projector's resolution, pixels; the monitor must run at it or offer it as a mode.
        x, y: where the projector's top-left pixel is on its monitor, when the projector is a region of a wider one
            (projectors side by side on one monitor, as a video wall controller or a graphics card's mosaic mode
            shows them; the device twin's projectors of several light field interfaces): the window is then a
            borderless window of width x height there, the monitor at least that large. None (both): the projector
            is the whole monitor, and the window full screen.
        bits: bit depth of the projector's codes (8: uint8 images; 9..16: uint16 images).
        settle_s: seconds waited after showing an image before a capture counts (display and camera latency;
            written by :func:`~lftransfer.rig.hardware.calibrate_latency`).
        drop_frames: camera frames dropped after each projection or set-up (frames the driver buffered
            before the new image was on).
        stale_check: after each projection or set-up, cameras read continuously (streams) compare their first
            frames; a frame that still changed after ``settle_s`` (``settle_s`` too short) is dropped, the capture
            waits for the image to hold still, and the rig counts and logs it (:class:`HardwareRig`).
        timeout_s: longest wait for the window to open or for one frame to be shown, seconds.
    """

    display: NonNegInt = 0
    x_display: str | None = None
    width: PosInt
    height: PosInt
    x: NonNegInt | None = None
    y: NonNegInt | None = None
    bits: Annotated[int, _Num, Field(ge=8, le=16)] = 8
    settle_s: NonNegFloat = 0.1
    drop_frames: NonNegInt = 1
    stale_check: bool = True
    timeout_s: PosFloat = 10.0


    @model_validator(mode="after")
    def _region(self) -> "ProjectorConfig":
        if (self.x is None) != (self.y is None):
            raise ValueError("x and y: give both (the projector's region on its monitor) or neither (the whole "
                             "monitor)")
        return self


class OperatorConfig(_Model):
    """Who arranges the set-ups a run asks for (a board in front of the array, the point light on, ...).

    Attributes:
        kind: ``"terminal"``: a person, asked at the terminal (the default); ``"http"``: an endpoint (a motorised
            stage's controller, the device twin) that gets each set-up as JSON by POST to ``url`` and answers
            once it is done; ``"command"``: a program run with the set-up as JSON on its standard input, done
            when it exits with status 0.
        url: the endpoint of ``kind = "http"``.
        command: the program of ``kind = "command"`` (split like a shell line, no shell).
        timeout_s: longest wait for an endpoint or a command to say it is done, seconds.
    """

    kind: Literal["terminal", "http", "command"] = "terminal"
    url: str | None = None
    command: str | None = None
    timeout_s: PosFloat = 600.0

    @model_validator(mode="after")
    def _needs(self) -> "OperatorConfig":
        if self.kind == "http" and not (self.url or "").startswith(("http://", "https://")):
            raise ValueError("kind = \"http\" needs url = the endpoint (http://...)")
        if self.kind == "command" and not (self.command or "").strip():
            raise ValueError("kind = \"command\" needs command = the program to run")
        return self


class HardwareRigConfig(_Model):
    """A rig file.

    Attributes:
        lf_camera: the LF camera behind the lens array.
        view_camera: the view camera (the rig's radiometric reference). None only in the rig file of a scene's
            second or later light field interface, which uses the first one's
            (:func:`~lftransfer.rig.hardware.open_interfaces`).
        projector: the projector behind the lens array.
        operator: who arranges the set-ups (:class:`OperatorConfig`; a person at the terminal by default).
        source: the file it was read from (set by :func:`load_rig_file`), or None.
    """

    lf_camera: CameraConfig
    view_camera: ViewCameraConfig | None = None
    projector: ProjectorConfig
    operator: OperatorConfig = OperatorConfig()
    source: Path | None = None

    @property
    def info(self) -> RigInfo:
        """The :class:`~lftransfer.rig.requests.RigInfo` this rig file describes (RigFileError without a view
        camera)."""
        if self.view_camera is None:
            raise RigFileError(f"{self.source or '<rig>'}: view_camera: missing: only the rig file of a scene's second "
                               "or later light field interface may leave it out (it uses the first one's)")
        return RigInfo(lf_camera=(self.lf_camera.width, self.lf_camera.height), lf_camera_bits=self.lf_camera.bits,
                       projector=(self.projector.width, self.projector.height),
                       projector_bits=self.projector.bits,
                       view=(self.view_camera.width, self.view_camera.height), kind="hardware")


# -- loading ---------------------------------------------------------------------------------------------------

def _rig_file_error(name: str, exc: ValidationError, data: dict) -> RigFileError:
    # a union (response_gamma = number | list) reports one error per member: keep the first of each field
    return RigFileError(validation_message(name, exc, root="<rig>", first_per_field=True, model=HardwareRigConfig,
                                           data=data))


def parse_rig_file(data: dict, name: str = "<rig>", base_dir: str | Path | None = None) -> HardwareRigConfig:
    """Validate rig file contents already read.

    Args:
        data: the parsed TOML tables.
        name: how messages name the file.
        base_dir: folder relative file paths (sources, ``cti``) are taken from, or None to keep them as given.

    Returns:
        The validated rig file.

    Raises:
        RigFileError: an invalid field (one line naming ``name`` and the field path).
    """
    if "source" in data:
        raise RigFileError(f"{name}: source: not a rig file field (it is set by the loader), found "
                           f"{data['source']!r}")
    try:
        return HardwareRigConfig.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as exc:
        raise _rig_file_error(name, exc, data) from None


def load_rig_file(path: str | Path) -> HardwareRigConfig:
    """Read and validate a rig file.

    Args:
        path: the TOML file; relative device paths inside it are relative to its folder.

    Returns:
        The validated rig file, ``source`` set to the file's absolute path.

    Raises:
        RigFileError: unreadable file, malformed TOML or an invalid field; one line naming the file and the
            field path (e.g. ``rig.toml: lf_camera.width: Input should be greater than 0, found -3``).
    """
    path = Path(path)
    data = read_toml(path, "rig file", RigFileError)
    config = parse_rig_file(data, str(path), path.resolve().parent)
    return config.model_copy(update={"source": path.resolve()})


# -- writing a value back --------------------------------------------------------------------------------------

_HEADER = re.compile(r"^\s*\[(?!\[)\s*([^\]]+?)\s*\]\s*(#.*)?$")


def _toml_scalar(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        v = float(value)
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        text = repr(v)
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
        return f'"{escaped}"'
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as a TOML scalar")


def _header_name(raw: str) -> str:
    return ".".join(p.strip().strip('"').strip("'") for p in raw.split("."))


def _line_edit(text: str, table: str, key: str, value: Any) -> str | None:
    """``text`` with ``table.key = value`` set by editing lines, or None where the layout is not a plain one."""
    lines = text.splitlines(keepends=True)
    key_re = re.compile(r"^([ \t]*)(" + re.escape(key) + r'|"' + re.escape(key) + r'"|\'' + re.escape(key) +
                        r"')([ \t]*=[ \t]*)([^#\r\n]*?)([ \t]*)(#[^\r\n]*)?(\r?\n)?$")
    current: str | None = None
    start = None                # index of the table's header line
    last_key = None             # index of the table's last key line
    for i, line in enumerate(lines):
        m = _HEADER.match(line)
        if m:
            current = _header_name(m.group(1))
            if current == table:
                if start is not None:
                    return None     # the table twice: not valid TOML anyway
                start = i
            continue
        if current != table:
            continue
        km = key_re.match(line)
        if km:
            indent, k, eq, _, space, comment, end = km.groups()
            if not comment:
                space = ""
            lines[i] = f"{indent}{k}{eq}{_toml_scalar(value)}{space}{comment or ''}{end or ''}"
            return "".join(lines)
        if line.strip() and not line.lstrip().startswith("#"):
            last_key = i
    new_line = f"{key} = {_toml_scalar(value)}\n"
    if start is None:
        sep = "" if not text or text.endswith("\n") else "\n"
        return text + sep + f"\n[{table}]\n" + new_line
    at = (last_key if last_key is not None else start) + 1
    if at > 0 and not lines[at - 1].endswith("\n"):
        lines[at - 1] += "\n"
    lines.insert(at, new_line)
    return "".join(lines)


def write_rig_value(path: str | Path, field: str, value: Any) -> HardwareRigConfig:
    """Set one field of a rig file, keeping everything else, and replace the file atomically.

    A line edit keeps every other line and comment (the value's own trailing comment too); the edited text is
    parsed again and must equal the old contents with only this field changed and be a valid rig file.
    Where the layout defeats the line edit (the table inline or as dotted keys), the file is rewritten whole
    with ``tomli_w`` (the ``hardware`` extra): same values, comments lost, a warning logged.

    Args:
        path: the rig file.
        field: ``"table.key"``, e.g. ``"projector.settle_s"``.
        value: the new value (a number, bool or string).

    Returns:
        The rig file as now written, validated.

    Raises:
        RigFileError: unreadable or invalid file, unknown field, or a value the rig file rejects (the file is
            then left unchanged).
    """
    path = Path(path)
    table, _, key = field.partition(".")
    if not table or not key or "." in key:
        raise RigFileError(f"{path}: {field}: expected a field as table.key (e.g. projector.settle_s)")
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except OSError as exc:
        raise RigFileError(f"{path}: cannot read the rig file: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise RigFileError(f"{path}: <toml>: malformed TOML: {exc}") from None
    expected = copy.deepcopy(data)
    expected.setdefault(table, {})
    if not isinstance(expected[table], dict):
        raise RigFileError(f"{path}: {table}: expected a table, found {expected[table]!r}")
    expected[table][key] = value
    config = parse_rig_file(copy.deepcopy(expected), str(path), path.resolve().parent)

    new_text = _line_edit(text, table, key, value)
    ok = False
    if new_text is not None:
        try:
            ok = tomllib.loads(new_text) == expected
        except tomllib.TOMLDecodeError:
            ok = False
    if not ok:
        try:
            import tomli_w
        except ImportError:
            raise RigFileError(f"{path}: {field}: the file's layout needs a full rewrite, which needs tomli_w "
                               "(pip install lftransfer[hardware]); or set the value by hand") from None
        _log.warning("%s: %s written by rewriting the whole file (its layout defeats a line edit); comments "
                     "are lost", path, field)
        new_text = tomli_w.dumps(expected)
    mode = None
    try:
        mode = os.stat(path).st_mode & 0o7777
    except OSError:
        pass
    write_text(path, new_text)
    if mode is not None:
        try:
            os.chmod(path, mode)
        except OSError:
            pass
    return config.model_copy(update={"source": path.resolve()})
