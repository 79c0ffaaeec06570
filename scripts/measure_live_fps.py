"""Frames per second of ``lft live`` as a page sees them, with a synthetic object moving.

Starts the live loop and its page server in this process, connects to the page's websocket like a browser,
moves the first synthetic object back and forth (an edit every 0.25 s) and counts the frames delivered over the
measurement window, after the first frame (kernel compilation) has arrived.

Usage:
    python scripts/measure_live_fps.py [SCENE.toml] [--quick] [--seconds 60] [--calibration FILE]
        [--rig-model calibrated|nominal|oracle]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import threading
import time
from pathlib import Path

from lftransfer.choices import DEFAULT_RIG_MODEL, RIG_MODELS


async def _watch(url: str, seconds: float, start_translate: list[float]) -> tuple[int, float, dict]:
    import websockets

    async with websockets.connect(url, max_size=None) as ws:
        frames, first, last_stages = 0, None, {}
        t_end = None
        step = 0
        while True:
            msg = json.loads(await ws.recv())
            if msg.get("type") != "frame":
                continue
            now = time.perf_counter()
            if first is None:
                first, t_end = now, now + seconds
                continue
            frames += 1
            last_stages = msg["stages_ms"]
            step += 1
            offset = 0.01 * ((step % 8) - 4)
            await ws.send(json.dumps({"type": "object", "side": "synthetic", "index": 0,
                                      "translate": [start_translate[0], start_translate[1] + offset,
                                                    start_translate[2]]}))
            if now >= t_end:
                return frames, now - first, last_stages


def main() -> None:
    import uvicorn

    from lftransfer.app.cli.common import load
    from lftransfer.app.viewer.command import open_session
    from lftransfer.app.viewer.server import make_app

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", type=Path, default=None)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--calibration", type=Path, default=None)
    parser.add_argument("--rig-model", default=DEFAULT_RIG_MODEL, choices=RIG_MODELS)
    parser.add_argument("--port", type=int, default=8787)
    args = parser.parse_args()
    scene = load(args.scene, args.quick)
    session = open_session(scene, rig_model=args.rig_model, calibration=args.calibration, out=Path("/tmp/lft-live-fps"))
    server = uvicorn.Server(uvicorn.Config(make_app(session), host="127.0.0.1", port=args.port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.1)
    frames, elapsed, stages = asyncio.run(_watch(f"ws://127.0.0.1:{args.port}/ws", args.seconds,
                                                 list(scene.synthetic[0].translate)))
    server.should_exit = True
    thread.join(60)
    view = scene.view.resolution
    print(json.dumps({"scene": str(scene.source), "view": view, "lf_camera": scene.rig.lf_camera,
                      "frames": frames, "seconds": round(elapsed, 2),
                      "frames_per_second": round(frames / elapsed, 4) if elapsed > 0 else None,
                      "last_frame_stages_ms": stages}, indent=2))


if __name__ == "__main__":
    main()
