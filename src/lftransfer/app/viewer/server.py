"""The web face of ``lft live``: FastAPI serves one page and a websocket; uvicorn runs it.

- ``GET /``: the page (a jinja2 template with autoescaping, no external assets);
- ``GET /health``: ``{"frames": N, "paused", "error", "bounces"}`` (the last bounce layers' state), for scripts
  and tests;
- ``WS /ws``: the page sends JSON edits (:meth:`LiveSession.submit`) and gets the scene's controls, every new
  frame of the layer it shows, acknowledgements and error messages. Any number of pages may watch; a page that
  goes away is dropped, the loop goes on. The bounce layers one page asks for (``{"type": "bounces"}``) go to
  every page connected (messages of type "bounces": running with its step, then done with the layers, or
  failed with the reason), so all watching tabs show them and know the live loop waits meanwhile; so do the
  ground-truth comparison (``{"type": "compare"}``: messages of type "compare") and the recording
  (``{"type": "record", "on": true|false}``: "recording", then "recorded" with the file).

The live loop runs on its own thread (:class:`LiveSession`); frames reach the event loop through
``asyncio.run_coroutine_threadsafe``, so rendering never blocks a page.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from pathlib import Path

from fastapi import FastAPI, WebSocket, WebSocketDisconnect
from fastapi.responses import HTMLResponse
from fastapi.websockets import WebSocketState
from jinja2 import Environment, FileSystemLoader, select_autoescape

from lftransfer.app.viewer.session import EditError, LiveSession, ViewerBounces, ViewerFrame

__all__ = ["make_app", "serve"]

TEMPLATES = Path(__file__).parent / "templates"


class _Clients:
    """The connected pages and the layer each shows."""

    def __init__(self) -> None:
        self.layers: dict[object, str] = {}
        self.last: ViewerFrame | None = None
        self.frames = 0

    async def send(self, ws, message: dict) -> bool:
        try:
            await ws.send_text(json.dumps(message))
            return True
        except Exception:  # noqa: BLE001 - a page that went away
            self.layers.pop(ws, None)
            return False

    async def broadcast_frame(self, frame: ViewerFrame) -> None:
        self.last = frame
        self.frames += 1
        for ws, layer in list(self.layers.items()):
            await self.send(ws, frame.message(layer))

    async def broadcast(self, message: dict) -> None:
        for ws in list(self.layers):
            await self.send(ws, message)


def make_app(session: LiveSession, *, title: str = "lft live"):
    """The FastAPI application around a session; the session's loop starts with the app, and the session is closed
    with it (its rig released).

    (FastAPI and jinja2 are imported at module level: FastAPI resolves the handlers' annotations, such as
    ``WebSocket``, from this module's names.)"""
    env = Environment(loader=FileSystemLoader(TEMPLATES), autoescape=select_autoescape(["html"]))
    clients = _Clients()

    @contextlib.asynccontextmanager
    async def lifespan(_app):
        loop = asyncio.get_running_loop()

        def on_frame(frame: ViewerFrame) -> None:
            asyncio.run_coroutine_threadsafe(clients.broadcast_frame(frame), loop)

        def on_error(message: str) -> None:
            asyncio.run_coroutine_threadsafe(clients.broadcast({"type": "error", "message": message}), loop)

        def on_bounces(bounces: ViewerBounces) -> None:
            asyncio.run_coroutine_threadsafe(clients.broadcast(bounces.message()), loop)

        def on_message(message: dict) -> None:
            asyncio.run_coroutine_threadsafe(clients.broadcast(message), loop)

        session.start(on_frame, on_error, on_bounces, on_message)
        try:
            yield
        finally:
            await asyncio.to_thread(session.close)

    app = FastAPI(title=title, lifespan=lifespan)

    @app.get("/", response_class=HTMLResponse)
    async def page() -> str:
        return env.get_template("live.html").render(title=title, scene=session.describe())

    @app.get("/health")
    async def health() -> dict:
        last = session.last_bounces
        return {"frames": clients.frames, "paused": session.paused, "error": session.error, "loop": session.live.loop,
                "capture_hz": session.live.capture_rate_hz, "recording": session.recorder.recording,
                "bounces": None if last is None else {"state": last.state, "bounces": last.bounces,
                                                      "elapsed_s": last.elapsed_s, "error": last.error}}

    @app.websocket("/ws")
    async def socket(ws: WebSocket) -> None:
        await ws.accept()
        clients.layers[ws] = "composite"
        await clients.send(ws, session.describe())
        if clients.last is not None:
            await clients.send(ws, clients.last.message("composite"))
        try:
            while True:
                text = await ws.receive_text()
                try:
                    payload = json.loads(text)
                    ack = session.submit(payload)
                    if payload.get("type") == "layer":
                        clients.layers[ws] = payload["layer"]
                    if payload.get("type") in ("object", "lighting_model", "exchanges", "pause", "resume", "record"):
                        await clients.broadcast({"type": "edited", "edit": payload})
                    await clients.send(ws, ack)
                except (EditError, json.JSONDecodeError) as exc:
                    await clients.send(ws, {"type": "error", "message": str(exc)})
        except WebSocketDisconnect:
            pass
        except RuntimeError:
            # a page that went away while a frame was being sent to it: the failed send closed the socket, and
            # the next receive raises (starlette's WebSocketDisconnected, a RuntimeError) instead of
            # WebSocketDisconnect. Anything else is a real fault.
            if ws.application_state != WebSocketState.DISCONNECTED:
                raise
        finally:
            clients.layers.pop(ws, None)

    app.state.clients = clients
    return app


def serve(session: LiveSession, *, host: str = "127.0.0.1", port: int = 8080, log_level: str = "warning") -> None:
    """Run the page until Ctrl-C (uvicorn handles the signal and the app stops the loop), or until the session's
    loop ends on its own (its rig failed: ``session.failed`` says why)."""
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(make_app(session), host=host, port=port, log_level=log_level))

    def watch() -> None:
        while not server.should_exit:
            if session.failed is not None:
                server.should_exit = True
            time.sleep(0.2)

    threading.Thread(target=watch, name="lft-live-watch", daemon=True).start()
    server.run()
