"""The simulated rig in a process of its own (docs/architecture.md, "The live loop"): the simulator out of the
renderer's way.

On the simulated rig a capture is a path-traced render. Run on the live loop's capture thread it shares the
renderer's Dr.Jit thread pool and cores, and the page keeps under a third of its frame rate.
:class:`SimulatorProcess` runs the same :class:`~lftransfer.sim.rig.SimRig` in a child process instead, with a thread
budget of its own and a lower scheduling priority (``nice``), so that the operating system gives the renderer the
cores whenever it wants them and the simulator the rest. The pipeline talks to it through the
:class:`~lftransfer.rig.base.Rig` protocol as to any rig; the simulated rig's own further methods (posing a real
object, its random streams) are forwarded too. Requests and answers cross a socket pair as pickles: an LF camera and
a view capture at the paper's resolution, 28 MB, take 80 to 130 ms on 2 cores, beside the capture's own seconds of
path tracing.

The child builds the rig from the scene and the truth seed exactly as
:func:`~lftransfer.sim.oracle.open_simulated_rig` does in process: its captures are the same to the bit, whatever
its thread count (tests/sim/test_process.py).

A child that dies (killed, out of memory) makes the request in progress and every later one raise a
:class:`~lftransfer.rig.base.RigError` of one line that names the simulator process, its pid and exit code.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import traceback
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from lftransfer import choices
from lftransfer.rig.base import RigError
from lftransfer.rig.requests import RigInfo

__all__ = ["SimulatorProcess"]

log = logging.getLogger(__name__)

START_TIMEOUT_S = 300.0      # the child's set-up (Mitsuba, the scene, its kernels) must finish within this
POLL_S = 0.25                # how often a waiting request looks whether the child still lives


def _serve(conn: Connection) -> None:
    """The child: take ``(scene, truth_seed, capture_spp, threads, nice, variant, pausable)``, build the simulated
    rig, then answer requests ``(name, args, kwargs)`` until ``close`` or the parent goes away.

    Answers are ``("ok", value)`` or ``("error", exception)`` (an exception that does not pickle travels as a
    RuntimeError of its text). The first answer is ``("ready", (info, methods, properties))``.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # Ctrl-C is the parent's to handle: it closes the child
    try:
        scene, truth_seed, capture_spp, threads, nice, variant, pausable = conn.recv()
        if pausable:
            _die_with_parent()
        if nice:
            os.nice(int(nice))
        from lftransfer.backend import set_drjit_threads

        set_drjit_threads(threads, variant)
        from lftransfer.sim.oracle import open_simulated_rig

        rig, _oracle = open_simulated_rig(scene, truth_seed, capture_spp=capture_spp)
        kind = type(rig)
        methods = sorted(n for n in dir(kind) if not n.startswith("_") and callable(getattr(kind, n)))
        properties = sorted(n for n in dir(kind) if not n.startswith("_") and isinstance(getattr(kind, n), property))
        conn.send(("ready", (rig.info, methods, properties)))
    except BaseException as exc:  # noqa: BLE001 - told to the parent, which raises it
        conn.send(("error", _portable(exc)))
        return
    while True:
        try:
            name, args, kwargs = conn.recv()
        except EOFError:                       # the parent went away
            break
        try:
            value = getattr(rig, name)
            if callable(value):
                value = value(*args, **kwargs)
            conn.send(("ok", value))
        except BaseException as exc:  # noqa: BLE001 - the request's error, raised in the parent
            conn.send(("error", _portable(exc)))
        if name == "close":
            break
    conn.close()


def _die_with_parent() -> None:
    """Ask Linux to kill this process when the thread that started it ends (``PR_SET_PDEATHSIG``): a child its parent
    stopped (:meth:`SimulatorProcess.pause`) could not see its socket close. Elsewhere the socket's end is the only
    sign."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)                   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it pickles, else a RuntimeError carrying its type and text."""
    import pickle

    try:
        pickle.dumps(exc)
        return exc
    except Exception:  # noqa: BLE001 - anything that fails to pickle
        text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        return RuntimeError(f"{text} (in the simulator process)")


class SimulatorProcess:
    """The simulated rig of ``scene`` in a child process: a :class:`~lftransfer.rig.base.Rig`.

    Args:
        scene: the whole scene (the rig's hidden world), as for :func:`~lftransfer.sim.oracle.open_simulated_rig`.
        truth_seed: the hidden truth's seed.
        capture_spp: rays per LF camera pixel.
        threads: Dr.Jit threads of the child (>= 1).
        nice: how much lower the child's scheduling priority is than this process's (0 .. 19; 0: the same).
        pausable: allow :meth:`pause`. The child is then killed by Linux when the thread that made this object ends
            (a stopped child could not see its parent go), so that thread must outlive the rig.

    Raises:
        ValueError: ``threads`` or ``nice`` out of range.
        RigError: the child died while starting, or did not start within :data:`START_TIMEOUT_S`.
        Exception: the child's own error where building the rig failed (of its own type where it pickles).
    """

    def __init__(self, scene, truth_seed: int | None, *, capture_spp: int,
                 threads: int = choices.DEFAULT_SIMULATOR_THREADS, nice: int = choices.DEFAULT_SIMULATOR_NICE,
                 pausable: bool = False) -> None:
        from lftransfer.backend import variant

        if not (isinstance(threads, int) and threads >= 1):
            raise ValueError(f"simulator threads: expected an integer >= 1, got {threads!r}")
        if not (isinstance(nice, int) and 0 <= nice <= 19):
            raise ValueError(f"simulator nice: expected an integer from 0 to 19, got {nice!r}")
        self.threads, self.nice = threads, nice
        # a fresh interpreter (no Dr.Jit state or threads inherited; the caller's main module is not imported again)
        ours, theirs = socket.socketpair()
        package_root = str(Path(__file__).resolve().parents[2])
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH"))
                                                            if p)}
        self._process = subprocess.Popen([sys.executable, "-m", "lftransfer.sim.process", str(theirs.fileno())],
                                         pass_fds=[theirs.fileno()], env=env)
        theirs.close()                              # the child's end lives in the child only: its death is an EOF
        self._conn = Connection(ours.detach())
        self._lock = threading.Lock()               # one request at a time (the capture thread and the loop's)
        self._dead: str | None = None
        self._closed = False
        self._stopped = False                       # pause(): the child is stopped (SIGSTOP) until resume()
        self.pausable = bool(pausable)
        self._conn.send((scene, truth_seed, int(capture_spp), threads, nice, variant(), self.pausable))
        info, methods, properties = self._answer("start", START_TIMEOUT_S, expect="ready")
        self._info: RigInfo = info
        self._methods, self._properties = frozenset(methods), frozenset(properties)
        # the real objects as they stand, kept here so that the page reads them without waiting for a capture
        self._real_objects = self._call("real_objects") if "real_objects" in self._properties else None

    @property
    def pid(self) -> int:
        """The child's process id."""
        return int(self._process.pid)

    @property
    def info(self) -> RigInfo:
        return self._info

    def cpu_seconds(self) -> float | None:
        """CPU seconds the child has used so far, all its threads, read from ``/proc`` without waiting for it (None
        where there is no ``/proc``, or once it has ended)."""
        try:
            fields = Path(f"/proc/{self._process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return None
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")      # utime + stime

    @property
    def busy(self) -> bool:
        """Whether a request is in progress (a capture being rendered, or waiting while paused)."""
        return self._lock.locked()

    def pause(self) -> None:
        """Stop the child where it is (``SIGSTOP``): its threads take no core, and a request in progress waits, until
        :meth:`resume`. Idempotent; nothing to do once the child has ended.

        Raises:
            RuntimeError: the child was not started ``pausable``.
        """
        if not self.pausable:
            raise RuntimeError("this simulator process was not started pausable (SimulatorProcess(pausable=True))")
        if not self._stopped and self._dead is None and not self._closed and self._process.poll() is None:
            try:
                os.kill(self._process.pid, signal.SIGSTOP)
                self._stopped = True
            except ProcessLookupError:                # it ended meanwhile: the next request says so
                pass

    def resume(self) -> None:
        """Let a paused child go on (``SIGCONT``). Idempotent."""
        if self._stopped:
            self._stopped = False
            if self._process.poll() is None:          # not reaped: its pid is still its own
                try:
                    os.kill(self._process.pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass

    @property
    def real_objects(self) -> list:
        """The real objects as they stand now (kept from the child's answer at start and after each
        :meth:`place_real`)."""
        if self._real_objects is None:
            raise AttributeError("the simulated rig has no 'real_objects'")
        return list(self._real_objects)

    def place_real(self, objects) -> None:
        """Move the real objects (:meth:`lftransfer.sim.rig.SimRig.place_real`)."""
        self._call("place_real", objects)
        self._real_objects = self._call("real_objects")

    def _died(self, during: str) -> RigError:
        try:
            code = self._process.wait(1.0)
        except subprocess.TimeoutExpired:
            code = None
        self._dead = (f"the simulator process (pid {self._process.pid}) died (exit code {code}) during {during}; "
                      "the simulated rig is gone")
        return RigError(self._dead)

    def _answer(self, during: str, timeout: float | None = None, expect: str = "ok"):
        """The child's next answer to the request ``during`` (its error raised here)."""
        waited = 0.0
        while True:
            try:
                if self._conn.poll(POLL_S):
                    status, value = self._conn.recv()
                    break
            except (EOFError, OSError):
                raise self._died(during) from None
            waited += POLL_S
            if self._process.poll() is not None:
                raise self._died(during)
            if timeout is not None and waited > timeout:
                raise RigError(f"the simulator process (pid {self._process.pid}) did not answer {during} within "
                               f"{timeout:g} s")
        if status == "error":
            raise value
        if status != expect:
            raise RigError(f"the simulator process answered {during} with {status!r}, expected {expect!r}")
        return value

    def _call(self, name: str, *args, **kwargs) -> Any:
        if self._dead is not None:
            raise RigError(self._dead)
        if self._closed:
            raise RigError(f"the simulator process was closed; {name} needs an open rig")
        with self._lock:
            try:
                self._conn.send((name, args, kwargs))
            except (BrokenPipeError, OSError):
                raise self._died(name) from None
            return self._answer(name)

    # -- the Rig protocol -----------------------------------------------------------------------------------------
    def setup(self, request) -> None:
        self._call("setup", request)

    def project(self, image) -> None:
        self._call("project", image)

    def capture_lf(self, *args, **kwargs):
        return self._call("capture_lf", *args, **kwargs)

    def capture_view(self, *args, **kwargs):
        return self._call("capture_view", *args, **kwargs)

    def close(self) -> None:
        """Close the rig and end the child (idempotent; a dead child is only reaped)."""
        if self._closed:
            return
        self.resume()
        if self._dead is None and self._process.poll() is None:
            try:
                self._call("close")
            except RigError as exc:
                log.warning("%s", exc)
        self._closed = True
        self._conn.close()
        try:
            self._process.wait(10.0)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(5.0)

    # -- the simulated rig's further methods and properties ---------------------------------------------------------
    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        if name in self.__dict__.get("_properties", ()):
            return self._call(name)
        if name in self.__dict__.get("_methods", ()):
            return lambda *args, **kwargs: self._call(name, *args, **kwargs)
        raise AttributeError(f"the simulated rig has no {name!r}")

    def __enter__(self) -> "SimulatorProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


if __name__ == "__main__":              # the child: ``python -m lftransfer.sim.process FD``
    _serve(Connection(int(sys.argv[1])))
