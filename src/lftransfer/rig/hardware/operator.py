"""The operator channel: who arranges a set-up the pipeline asks a physical rig for.

A set-up (:data:`lftransfer.rig.requests.Setup`: a board held at a place, the collimator on, the real scene with
its point light on, ...) is physical work. The rig file's ``[operator]`` table (:class:`~.config.OperatorConfig`)
says who does it:

- ``terminal`` (default): a person. The rig calls the operator callback it was given with the set-up's prompt
  (the CLI prints it and waits for Enter).
- ``http``: an endpoint, such as a motorised stage's controller or the device twin (:mod:`lftransfer.sim.twin`).
  The set-up goes by POST as JSON, ``{"setup": describe(request), "prompt": "..."}``; the endpoint answers once it
  is done, ``{"done": true}`` (or ``{"done": false, "error": "why"}``).
- ``command``: a program, given the same JSON on its standard input; done when it exits with status 0.

An endpoint also gets later moments of an animated real scene (``RealScene(time_s)``), which a stage can pose
and a person cannot; the terminal is asked only when the set-up changes kind.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import urllib.error
import urllib.request
from typing import Callable

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.config import OperatorConfig
from lftransfer.rig.requests import Setup, describe

__all__ = ["Arrange", "arranger"]

Arrange = Callable[[Setup], None]
"""Arranges a set-up and returns once it is done (raises RigError where it could not be done)."""


def _message(request: Setup) -> bytes:
    return json.dumps({"setup": describe(request), "prompt": request.prompt()}).encode()


def _http(url: str, timeout_s: float) -> Arrange:
    def arrange(request: Setup) -> None:
        req = urllib.request.Request(url, data=_message(request), method="POST",
                                     headers={"Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=timeout_s) as answer:
                reply = json.loads(answer.read().decode() or "{}")
        except urllib.error.HTTPError as exc:
            body = exc.read().decode(errors="replace")[:300]
            raise RigError(f"operator endpoint {url}: the set-up {request.kind} was refused (HTTP {exc.code}: "
                           f"{body})") from None
        except (urllib.error.URLError, TimeoutError, OSError) as exc:
            why = getattr(exc, "reason", exc)
            raise RigError(f"operator endpoint {url}: no answer to the set-up {request.kind} within {timeout_s:g} s "
                           f"({why})") from None
        if not reply.get("done"):
            raise RigError(f"operator endpoint {url}: the set-up {request.kind} was not done: "
                           f"{reply.get('error', reply)}")
    return arrange


def _command(command: str, timeout_s: float) -> Arrange:
    argv = shlex.split(command)

    def arrange(request: Setup) -> None:
        try:
            done = subprocess.run(argv, input=_message(request), capture_output=True, timeout=timeout_s)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise RigError(f"operator command {argv[0]}: the set-up {request.kind} failed: {exc}") from None
        if done.returncode != 0:
            raise RigError(f"operator command {argv[0]}: the set-up {request.kind} failed (exit status "
                           f"{done.returncode}): {done.stderr.decode(errors='replace')[-300:]}")
    return arrange


def arranger(config: OperatorConfig, prompt: Callable[[str], None]) -> tuple[Arrange, bool]:
    """The operator a rig file names.

    Args:
        config: the rig file's ``[operator]`` table.
        prompt: the person's callback (gets a prompt, returns when done), used for ``kind = "terminal"``.

    Returns:
        (arrange, endpoint): ``endpoint`` is True for an HTTP endpoint or a command (they also pose the moments of an
        animated real scene).
    """
    if config.kind == "http":
        return _http(str(config.url), config.timeout_s), True
    if config.kind == "command":
        return _command(str(config.command), config.timeout_s), True
    return (lambda request: prompt(request.prompt())), False
