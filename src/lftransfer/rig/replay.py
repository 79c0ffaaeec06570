"""Recording a rig and replaying the recording (docs/architecture.md, "The rig boundary").

:class:`RecordingRig` wraps any :class:`~lftransfer.rig.base.Rig`, forwards every call and stores every request
and every answer; :class:`ReplayRig` is a rig that answers from such a recording, so a run on a physical rig can
be reproduced offline, bit for bit.

A recording is a folder::

    manifest.json                 format and version, package versions, the rig's info, the caller's meta and
                                  one entry per event in call order (see below); rewritten atomically after
                                  every capture, "complete": true once closed
    projector/<digest[:16]>.png   each projector image once, as projected (8- or 16-bit RGB PNG), for viewing
    lf/<event:06d>.png            LF camera frames: 16-bit RGB PNG of the codes as they are (``bits`` bits, not
                                  scaled to 16 bits, so a viewer shows a 12-bit frame dark)
    view/<event:06d>.pfm          view camera frames: float32 RGB portable float map (raw float32), linear
                                  radiance; .exr (OpenEXR, PIZ) with ``view_format="exr"``

Events (``manifest["events"]``, ``index`` = position, which also names the files)::

    {"event": "setup", "setup": describe(setup)}
    {"event": "project", "digest": image_digest(image), "shape", "dtype", "file", "sha256"}
    {"event": "capture_lf" | "capture_view", "setup": describe(current set-up), "projected": digest or null,
     "request": describe(request), "key": request_key(...), "shape", "dtype", "file", "sha256",
     "bits" and "exposure_scale" (LF only), "capture_s" (the rig's time), "store_s" (encoding and writing)}

Formats: the LF codes are uint16 and a 16-bit PNG holds them losslessly and opens in any viewer; it is written
with OpenCV (zlib level 1, Huffman-only, "sub" filter: sensor noise leaves little for LZ77 to find, so this is
about twice as fast as OpenCV's default for a file 5 % smaller). View frames are float32: a portable float map
(OpenCV) stores their bits as they are. Mitsuba's ``Bitmap`` also keeps float32 when it writes OpenEXR (PIZ,
lossless: every bit pattern, NaN payloads and -0.0 included, reads back unchanged), but PIZ gains about 1 % on
noisy float32 and costs some 0.5-0.9 CPU seconds per 1024 x 768 frame against 0.02-0.04 s for PFM, so EXR is
the option, PFM the default. An answer that is not (H, W, 3) uint8/uint16 (LF) or float32 (view) is stored as
``.npy``, so that it too comes back exactly.

Encoding a 2048 x 1536 LF frame takes longer than a fast camera's capture (0.3-0.6 s on two cores), so by
default frames are encoded and written on ``workers`` background threads while the rig takes its next frames,
and one more thread adds each event to the manifest in call order once its file is written: a capture call
then only copies its answer (a few ms) as long as the storage keeps up. At most ``max_pending`` events wait to
be stored (then a call waits); a storage failure is raised (as :class:`~lftransfer.rig.base.RigError`) by the
next call, :meth:`RecordingRig.flush` or :meth:`RecordingRig.close`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import logging
import os
import platform
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

import lftransfer
from lftransfer.imageio_utils import _atomic_target, native_messages, read_exr, write_exr, write_text
from lftransfer.rig.base import Rig, RigError
from lftransfer.rig.requests import (SETUPS, LFCapture, LFFrame, RealScene, RigInfo, Setup, ViewCapture, ViewFrame,
                                     describe, image_digest, request_key)

__all__ = ["FORMAT", "FORMAT_VERSION", "MANIFEST", "RecordingRig", "ReplayError", "ReplayRig"]

log = logging.getLogger(__name__)

FORMAT = "lftransfer-rig-recording"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
_CAPTURES = ("capture_lf", "capture_view")
_CAPTURE_FIELDS = ("key", "setup", "projected", "request", "file", "sha256", "shape", "dtype")


class ReplayError(RigError):
    """A replay cannot answer: the recording lacks the request, or its manifest or a file is missing or
    corrupt."""


# -- storing and loading arrays -------------------------------------------------------------------------------

def _png_params() -> list[int]:
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):                  # OpenCV >= 4.11
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]
    return params


_PNG_PARAMS = _png_params()


def _is_rgb(a: np.ndarray, dtypes: tuple) -> bool:
    return a.ndim == 3 and a.shape[2] == 3 and a.shape[0] > 0 and a.shape[1] > 0 and a.dtype in dtypes


def _write_bytes(path: Path, data) -> None:
    """Write ``data`` (bytes-like) to ``path`` atomically (see :mod:`lftransfer.imageio_utils`)."""
    tmp = _atomic_target(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _suffix(a: np.ndarray, image_format: str) -> str:
    """File suffix array ``a`` is stored with: "." + ``image_format`` ("png": (H, W, 3) uint8/uint16; "exr",
    "pfm": (H, W, 3) float32), ".npy" for any other array."""
    if image_format == "png" and _is_rgb(a, (np.dtype(np.uint8), np.dtype(np.uint16))):
        return ".png"
    if image_format in ("exr", "pfm") and _is_rgb(a, (np.dtype(np.float32),)):
        return "." + image_format
    return ".npy"


def _store(path: Path, a: np.ndarray) -> str:
    """Write array ``a`` to ``path`` in the format its suffix names, atomically.

    Args:
        path: destination ending in ".png" ((H, W, 3) uint8/uint16, RGB), ".exr" or ".pfm" ((H, W, 3) float32)
            or ".npy" (any array).
        a: the array.

    Returns:
        The SHA-256 (hex) of the file written.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".exr":
        write_exr(path, a)
        return hashlib.sha256(path.read_bytes()).hexdigest()
    if path.suffix in (".png", ".pfm"):
        params = _PNG_PARAMS if path.suffix == ".png" else []
        ok, buf = cv2.imencode(path.suffix, cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2BGR), params)
        if not ok:
            raise RuntimeError(f"OpenCV could not encode a {a.shape} {a.dtype} image as {path.suffix}")
        data = memoryview(buf)
    else:
        stream = io.BytesIO()
        np.save(stream, a, allow_pickle=False)
        data = stream.getbuffer()
    _write_bytes(path, data)
    return hashlib.sha256(data).hexdigest()


def _decode(path: Path, data: bytes) -> np.ndarray:
    """The array a file written by :func:`_store` holds; ``data`` are its (already verified) bytes."""
    if path.suffix == ".exr":
        return read_exr(path)
    if path.suffix in (".png", ".pfm"):
        with native_messages() as said:
            a = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if a is None:
            raise ValueError(f"not a {path.suffix} file OpenCV can read" + (f" ({'; '.join(said)})" if said else ""))
        return cv2.cvtColor(a, cv2.COLOR_BGR2RGB) if a.ndim == 3 and a.shape[2] == 3 else a
    return np.load(io.BytesIO(data), allow_pickle=False)


def _versions() -> dict[str, str]:
    """Versions of Python and the packages that write and read a recording."""
    def dist(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "not installed"

    return {"lftransfer": lftransfer.__version__, "numpy": np.__version__, "opencv": cv2.__version__,
            "mitsuba": dist("mitsuba"), "drjit": dist("drjit"), "python": platform.python_version()}


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


# -- recording ------------------------------------------------------------------------------------------------

class _Storer:
    """Runs a recording's storage: file writing on ``workers`` threads, each event's commit (its manifest entry)
    on one more thread in call order; with ``workers`` 0 everything runs inside the call.

    After the first failure later commits are skipped (the recording would have a hole) and every call raises
    it.
    """

    def __init__(self, folder: Path, workers: int, max_pending: int) -> None:
        self._folder = folder
        self._files = ThreadPoolExecutor(workers, thread_name_prefix="lft-recording-file") if workers > 0 else None
        self._commits = ThreadPoolExecutor(1, thread_name_prefix="lft-recording") if workers > 0 else None
        self._pending: deque[Future] = deque()
        self._max_pending = max(1, int(max_pending))
        self._error: BaseException | None = None

    def _run(self, job: Callable[[], None]) -> None:
        if self._error is not None:
            return
        try:
            job()
        except Exception as exc:
            self._error = exc
            raise

    def check(self) -> None:
        """Raise the first storage failure, if any (RigError)."""
        while self._pending and self._pending[0].done():
            self._pending.popleft()
        if self._error is not None:
            raise RigError(f"recording to {self._folder}: storing failed ({type(self._error).__name__}: "
                           f"{self._error}); the recording holds what came before") from self._error

    def submit(self, commit: Callable[[object], None], write: Callable[[], object] | None = None) -> None:
        """Run ``write()`` (if given), then ``commit(what write returned)`` after every earlier commit; waits
        while ``max_pending`` events are queued."""
        self.check()
        if self._commits is None:
            try:
                self._run(lambda: commit(write() if write is not None else None))
            except Exception:
                self.check()
            return
        while len(self._pending) >= self._max_pending:
            self._pending.popleft().exception()
        written = self._files.submit(write) if write is not None else None
        self._pending.append(self._commits.submit(
            self._run, lambda: commit(written.result() if written is not None else None)))

    def flush(self) -> None:
        """Wait for every queued event; raise the first failure."""
        while self._pending:
            self._pending.popleft().exception()
        self.check()

    def shutdown(self) -> None:
        for pool in (self._commits, self._files):
            if pool is not None:
                pool.shutdown(wait=True)


class RecordingRig:
    """A rig that forwards every call to another rig and records requests and answers in a folder.

    The answers it returns are the inner rig's own objects; what it stores are copies taken at once, so the
    caller may change them. Calls that the inner rig refuses (it raises) are not recorded. Methods beyond the
    :class:`~lftransfer.rig.base.Rig` protocol are not forwarded (they would bypass the recording); the inner
    rig is :attr:`inner`.

    Args:
        inner: the rig to record.
        folder: where the recording goes (created; must not hold a recording already).
        meta: what the caller wants kept with the recording (e.g. the scene file and the truth seed); stored
            as JSON, values JSON does not know (paths, ...) as their ``str``.
        view_format: "pfm" (portable float map through OpenCV, raw float32) or "exr" (OpenEXR through
            Mitsuba, lossless PIZ: about 1 % smaller, some 20 times slower to write) for view frames.
        workers: threads that encode and write frames (they overlap with the rig's next captures and with one
            another); 0: store everything inside each call, no threads; None: 2 on four or more CPU cores,
            else 1.
        max_pending: events that may wait to be stored before a call waits for the storage (memory bound:
            each pending frame is a copy of it).

    Raises:
        FileExistsError: ``folder`` holds a recording already.
    """

    def __init__(self, inner: Rig, folder: str | os.PathLike, *, meta: dict | None = None,
                 view_format: str = "pfm", workers: int | None = None, max_pending: int = 6) -> None:
        if view_format not in ("pfm", "exr"):
            raise ValueError(f"view_format must be 'pfm' or 'exr', got {view_format!r}")
        if workers is None:
            workers = 2 if (os.cpu_count() or 1) >= 4 else 1
        self.folder = Path(folder)
        self._view_format = view_format
        if (self.folder / MANIFEST).exists():
            raise FileExistsError(f"{self.folder} holds a recording already ({MANIFEST}); choose a new folder")
        self._inner = inner
        self._manifest = {
            "format": FORMAT, "version": FORMAT_VERSION, "complete": False, "created": _now(),
            "versions": _versions(), "info": dataclasses.asdict(inner.info),
            "meta": json.loads(json.dumps(meta or {}, default=str)), "events": []}
        self._events: list[dict] = self._manifest["events"]     # changed by storage jobs only
        self._projector_files: dict[str, tuple[str, str]] = {}  # digest -> (file, sha256), storage jobs only
        self._saved_digests: set[str] = set()
        self._setup: Setup = RealScene()
        self._projected: str | None = None
        self._count = 0
        self._closed = False
        self._mitsuba_ready = False
        self._write_manifest()
        self._storer = _Storer(self.folder, int(workers), max_pending)

    # -- the protocol

    @property
    def info(self) -> RigInfo:
        """The inner rig's info."""
        return self._inner.info

    @property
    def inner(self) -> Rig:
        """The recorded rig."""
        return self._inner

    def setup(self, request: Setup) -> None:
        """Forward the set-up and record it (:data:`~lftransfer.rig.requests.Setup`)."""
        self._check_open()
        self._inner.setup(request)
        self._setup = request
        entry = {"index": self._next_index(), "event": "setup", "setup": describe(request)}
        self._storer.submit(lambda _: self._events.append(entry))

    def project(self, image: np.ndarray) -> None:
        """Forward the projector image ((H, W, 3) uint8 or uint16) and record its digest; each distinct image
        is also saved once under ``projector/``."""
        self._check_open()
        image = np.asarray(image)
        self._inner.project(image)
        digest = image_digest(image)
        self._projected = digest
        entry = {"index": self._next_index(), "event": "project", "digest": digest, "shape": list(image.shape),
                 "dtype": image.dtype.str}
        copy = None
        if digest not in self._saved_digests:
            self._saved_digests.add(digest)
            copy = image.copy()

        def write() -> tuple[str, str]:
            file = f"projector/{digest[:16]}{_suffix(copy, 'png')}"
            return file, _store(self.folder / file, copy)

        def commit(written: tuple[str, str] | None) -> None:
            if written is not None:
                self._projector_files[digest] = written
            entry["file"], entry["sha256"] = self._projector_files[digest]
            self._events.append(entry)

        self._storer.submit(commit, write if copy is not None else None)

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        """Forward the capture; record the request and the frame (its codes as a 16-bit PNG)."""
        self._check_open()
        start = time.perf_counter()
        frame = self._inner.capture_lf(request)
        elapsed = time.perf_counter() - start
        codes = np.array(frame.codes, copy=True)
        entry = self._capture_entry("capture_lf", request, codes, "lf", "png", elapsed)
        entry.update(bits=int(frame.bits), exposure_scale=float(frame.exposure_scale))
        self._storer.submit(self._commit_capture(entry), self._write_capture(entry, codes))
        return frame

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        """Forward the capture; record the request and the frame (float32 PFM or OpenEXR)."""
        self._check_open()
        start = time.perf_counter()
        frame = self._inner.capture_view(request)
        elapsed = time.perf_counter() - start
        radiance = np.array(frame.radiance, copy=True)
        entry = self._capture_entry("capture_view", request, radiance, "view", self._view_format, elapsed)
        if entry["file"].endswith(".exr") and not self._mitsuba_ready:
            from lftransfer.backend import mitsuba

            mitsuba()                     # pick the variant here, not on the storage thread
            self._mitsuba_ready = True
        self._storer.submit(self._commit_capture(entry), self._write_capture(entry, radiance))
        return frame

    def flush(self) -> None:
        """Wait until everything recorded so far is on disk (manifest included).

        Raises:
            RigError: storing failed.
        """
        self._storer.flush()

    def close(self) -> None:
        """Close the inner rig, finish storing and mark the manifest complete (idempotent).

        Raises:
            RigError: storing failed (the manifest then stays incomplete, holding what came before).
        """
        if self._closed:
            return
        self._closed = True
        try:
            self._inner.close()
        finally:
            try:
                self._storer.flush()
            finally:
                self._storer.shutdown()
            self._manifest["complete"] = True
            self._manifest["closed"] = _now()
            self._write_manifest()

    def __enter__(self) -> "RecordingRig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- helpers

    def _check_open(self) -> None:
        if self._closed:
            raise RigError(f"recording to {self.folder}: the rig is closed")
        self._storer.check()

    def _next_index(self) -> int:
        self._count += 1
        return self._count - 1

    def _capture_entry(self, event: str, request, a: np.ndarray, folder: str, image_format: str,
                       elapsed: float) -> dict:
        index = self._next_index()
        return {"index": index, "event": event, "setup": describe(self._setup), "projected": self._projected,
                "request": describe(request), "key": request_key(self._setup, self._projected, request),
                "shape": list(a.shape), "dtype": a.dtype.str, "file": f"{folder}/{index:06d}{_suffix(a, image_format)}",
                "capture_s": round(elapsed, 6)}

    def _write_capture(self, entry: dict, a: np.ndarray) -> Callable[[], tuple[str, float]]:
        def write() -> tuple[str, float]:
            start = time.perf_counter()
            return _store(self.folder / entry["file"], a), round(time.perf_counter() - start, 6)

        return write

    def _commit_capture(self, entry: dict) -> Callable[[tuple[str, float]], None]:
        def commit(written: tuple[str, float]) -> None:
            entry["sha256"], entry["store_s"] = written
            self._events.append(entry)
            self._write_manifest()

        return commit

    def _write_manifest(self) -> None:
        write_text(self.folder / MANIFEST, json.dumps(self._manifest, indent=1) + "\n")


# -- replaying ------------------------------------------------------------------------------------------------

def _short(digest: str | None) -> str:
    return "none" if digest is None else digest[:12]


def _json(data) -> str:
    return json.dumps(data, sort_keys=True)


class ReplayRig:
    """A rig that answers from a recording made by :class:`RecordingRig`.

    It follows set-ups and projections like a real rig and answers a capture with the recorded answer to the
    same request (:func:`~lftransfer.rig.requests.request_key`: set-up, projector image digest, request); the
    i-th asking of a request gets the i-th answer recorded for it. Files are read when asked for and their
    SHA-256 checked against the manifest.

    An incomplete recording (not closed: the run was interrupted) is replayed up to its last stored capture
    with a warning through :mod:`logging`, unless ``strict``.

    Args:
        folder: the recording.
        strict: refuse an incomplete recording.

    Raises:
        ReplayError: the manifest is missing, unreadable, of another format or (``strict``) incomplete.
    """

    def __init__(self, folder: str | os.PathLike, *, strict: bool = False) -> None:
        self.folder = Path(folder)
        self.manifest = self._read_manifest()
        events = self.manifest["events"]
        try:
            self.recorded_info = RigInfo(**{k: tuple(v) if isinstance(v, list) else v
                                            for k, v in self.manifest["info"].items()})
            self._answers: dict[str, list[dict]] = {}
            self._per_setup: dict[str, list[dict]] = {}
            self._projected_digests = {e["digest"] for e in events if e["event"] == "project"}
            for e in events:
                if e["event"] in _CAPTURES:
                    fields = _CAPTURE_FIELDS + (("bits", "exposure_scale") if e["event"] == "capture_lf" else ())
                    missing = [f for f in fields if f not in e]
                    if missing:
                        raise KeyError(f"event {e.get('index')} ({e['event']}) lacks {missing}")
                    self._answers.setdefault(e["key"], []).append(e)
                    self._per_setup.setdefault(_json(e["setup"]), []).append(e)
        except (KeyError, TypeError, ValueError) as exc:
            raise ReplayError(f"{self.folder}: {MANIFEST} is malformed ({type(exc).__name__}: {exc})") from exc
        self.captures = sum(len(v) for v in self._answers.values())
        if not self.manifest.get("complete"):
            if strict:
                raise ReplayError(f"{self.folder}: the recording is incomplete (never closed: the run was "
                                  f"interrupted?); it holds {self.captures} captures")
            log.warning("%s: the recording is incomplete (never closed: the run was interrupted?); replaying the "
                        "%d captures it holds", self.folder, self.captures)
        self._info = dataclasses.replace(self.recorded_info, kind="replay")
        self._served: dict[str, int] = {}
        self._setup: Setup = RealScene()
        self._projected: str | None = None
        self._closed = False

    # -- the protocol

    @property
    def info(self) -> RigInfo:
        """The recorded rig's info with kind "replay" (the recorded one is :attr:`recorded_info`)."""
        return self._info

    @property
    def meta(self) -> dict:
        """What the recording's caller stored with it (``RecordingRig(meta=...)``)."""
        return self.manifest.get("meta") or {}

    def setup(self, request: Setup) -> None:
        """Follow a set-up (:data:`~lftransfer.rig.requests.Setup`)."""
        self._check_open()
        if not isinstance(request, tuple(SETUPS.values())):
            raise TypeError(f"not a set-up: {request!r}")
        self._setup = request

    def project(self, image: np.ndarray) -> None:
        """Follow a projection ((H, W, 3) uint8 or uint16 as :attr:`info` says, else ValueError)."""
        self._check_open()
        self._projected = image_digest(self._info.check_projector_image(image))

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        """The recorded LF frame for this request in the current state.

        Returns:
            LFFrame with (H, W, 3) uint16 codes, bits and exposure scale as recorded.

        Raises:
            ReplayError: the recording holds no (more) answers for it, or its file is missing or corrupt.
        """
        entry = self._next_entry("capture_lf", request)
        return LFFrame(codes=self._load(entry), bits=int(entry["bits"]),
                       exposure_scale=float(entry["exposure_scale"]))

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        """The recorded view frame for this request in the current state.

        Returns:
            ViewFrame with (H, W, 3) float32 radiance as recorded.

        Raises:
            ReplayError: as :meth:`capture_lf`.
        """
        return ViewFrame(radiance=self._load(self._next_entry("capture_view", request)))

    def close(self) -> None:
        """Nothing to release (idempotent)."""
        self._closed = True

    def __enter__(self) -> "ReplayRig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- beyond the protocol

    def remaining(self) -> int:
        """Recorded captures not replayed yet."""
        return self.captures - sum(self._served.values())

    def verify(self) -> int:
        """Check every file the manifest names against its SHA-256.

        Returns:
            The number of files checked.

        Raises:
            ReplayError: naming the first missing or corrupt file.
        """
        files = {e["file"]: e["sha256"] for e in self.manifest["events"] if "file" in e}
        for file, sha in files.items():
            self._read_verified(file, sha)
        return len(files)

    # -- helpers

    def _read_manifest(self) -> dict:
        path = self.folder / MANIFEST
        if not path.is_file():
            raise ReplayError(f"{self.folder}: not a rig recording ({MANIFEST} missing)")
        try:
            manifest = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ReplayError(f"{self.folder}: {MANIFEST} unreadable ({exc})") from exc
        if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
            raise ReplayError(f"{self.folder}: {MANIFEST} is not a {FORMAT} manifest")
        if not isinstance(manifest.get("version"), int) or manifest["version"] > FORMAT_VERSION:
            raise ReplayError(f"{self.folder}: recording format version {manifest.get('version')!r}; this "
                              f"lftransfer reads up to {FORMAT_VERSION}")
        if not isinstance(manifest.get("events"), list) or not isinstance(manifest.get("info"), dict):
            raise ReplayError(f"{self.folder}: {MANIFEST} is malformed (no events or no info)")
        return manifest

    def _check_open(self) -> None:
        if self._closed:
            raise RigError(f"replay of {self.folder}: the rig is closed")

    def _state(self) -> str:
        if self._projected is None:
            where = "nothing projected yet"
        elif self._projected in self._projected_digests:
            where = "an image the recording projected"
        else:
            where = "an image never projected in the recording"
        return f"under set-up {_json(describe(self._setup))} with projector image {_short(self._projected)} ({where})"

    def _next_entry(self, event: str, request) -> dict:
        self._check_open()
        key = request_key(self._setup, self._projected, request)
        answers = self._answers.get(key, [])
        served = self._served.get(key, 0)
        what = f"{event} {_json(describe(request))}"
        if not answers:
            same_setup = self._per_setup.get(_json(describe(self._setup)), [])
            same_image = [e for e in same_setup if e["projected"] == self._projected]
            recorded = sorted({_json(e["request"]) for e in same_image})
            listing = f": {', '.join(recorded[:6])}{' ...' if len(recorded) > 6 else ''}" if recorded else ""
            raise ReplayError(
                f"replay of {self.folder}: {what} {self._state()} is not in the recording; it holds "
                f"{len(same_setup)} capture(s) under this set-up, {len(same_image)} of them with this projector "
                f"image{listing}")
        if served >= len(answers):
            raise ReplayError(f"replay of {self.folder}: {what} {self._state()} is asked for more often than "
                              f"recorded: the recording holds {len(answers)} answer(s) to it")
        self._served[key] = served + 1
        return answers[served]

    def _read_verified(self, file: str, sha256: str) -> tuple[Path, bytes]:
        path = self.folder / file
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ReplayError(f"replay of {self.folder}: cannot read {path} ({exc})") from exc
        got = hashlib.sha256(data).hexdigest()
        if got != sha256:
            raise ReplayError(f"replay of {self.folder}: {path} is corrupt or changed (SHA-256 {got[:12]}..., "
                              f"the manifest says {sha256[:12]}...)")
        return path, data

    def _load(self, entry: dict) -> np.ndarray:
        path, data = self._read_verified(entry["file"], entry["sha256"])
        try:
            a = _decode(path, data)
        except Exception as exc:  # noqa: BLE001 - any decoder failure is a bad file
            raise ReplayError(f"replay of {self.folder}: cannot decode {path} ({exc})") from exc
        shape, dtype = tuple(entry["shape"]), np.dtype(entry["dtype"])
        if a.shape != shape or a.dtype != dtype:
            raise ReplayError(f"replay of {self.folder}: {path} holds {a.shape} {a.dtype}, the manifest says "
                              f"{shape} {dtype}")
        return a
