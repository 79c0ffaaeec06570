"""Frames per second of ``lft live`` as a page sees them, and edit-to-pixel latency, decoupled against --sync.

For each loop asked for, starts a live session and its page server in this process, connects to the page's
websocket like a browser, and, after the first frame (kernel compilation, the first capture) has arrived, moves
the first synthetic object back and forth as a dragged slider does (an edit every 0.1 s). An edit's
edit-to-pixel latency is the time from sending it to receiving the first frame message that shows it (the frame's
``edits`` count reaches it; JPEG and websocket included). It counts the frame messages over the window.

Usage:
    python scripts/measure_live_fps.py [SCENE.toml] [--quick] [--seconds 60] [--loop both|decoupled|sync]
        [--calibration FILE] [--rig-model calibrated|nominal|oracle] [--edit-every 0.1] [--json OUT]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import threading
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from lftransfer.choices import DEFAULT_RIG_MODEL, LIVE_LOOPS, RIG_MODELS
from lftransfer.transfer.latency import LatencySpread

EDIT_EVERY_S = 0.1       # a slider being dragged: an edit every this many seconds
RSS_EVERY_S = 5.0        # resident memory sampled this often


def _rss_mb() -> float:
    """This process's resident set, MB (Linux /proc)."""
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


async def _watch(url: str, seconds: float, start_translate: list[float], edit_every: float = EDIT_EVERY_S) -> dict:
    import websockets

    async with websockets.connect(url, max_size=None) as ws:
        first_frame = asyncio.Event()
        sent_at: list[float] = []          # sent_at[n - 1]: when edit n was sent
        frames: list[tuple[float, int]] = []   # (received, edits shown)
        rss: list[tuple[float, float]] = []    # (seconds since the first frame, MB)
        last: dict = {}

        async def sample_memory() -> None:
            await first_frame.wait()
            t0 = time.perf_counter()
            while True:
                rss.append((round(time.perf_counter() - t0, 1), round(_rss_mb(), 1)))
                await asyncio.sleep(RSS_EVERY_S)

        async def send_edits() -> None:
            await first_frame.wait()
            end = time.perf_counter() + seconds
            while time.perf_counter() < end:
                n = len(sent_at) + 1
                offset = 0.01 * ((n % 8) - 4)
                sent_at.append(time.perf_counter())
                await ws.send(json.dumps({"type": "object", "side": "synthetic", "index": 0,
                                          "translate": [start_translate[0], start_translate[1] + offset,
                                                        start_translate[2]]}))
                await asyncio.sleep(edit_every)

        async def receive() -> None:
            started = None
            while True:
                msg = json.loads(await ws.recv())
                now = time.perf_counter()
                if msg.get("type") != "frame":
                    continue
                if started is None:
                    started = now
                    first_frame.set()
                    continue
                frames.append((now, int(msg["edits"])))
                last.update(msg)
                if now - started >= seconds and len(sent_at) and frames[-1][1] >= len(sent_at):
                    return
                if now - started >= seconds + 120:
                    return

        sender, sampler = asyncio.create_task(send_edits()), asyncio.create_task(sample_memory())
        await receive()
        sender.cancel()
        sampler.cancel()
        received = np.array([t for t, _ in frames])
        shown = np.array([e for _, e in frames])
        # edit n is seen in the first frame whose count reaches n
        latencies = []
        for n, at in enumerate(sent_at, start=1):
            hit = np.flatnonzero((shown >= n) & (received >= at))
            if len(hit):
                latencies.append(received[hit[0]] - at)
        window = received[received <= received[0] + seconds] if len(received) else received
        gaps = np.diff(received) if len(received) > 1 else np.zeros(0)
        spread = LatencySpread.of(np.array(latencies))
        span = float(window[-1] - window[0]) if len(window) > 1 else 0.0
        return {"frames": int(len(window)), "seconds": round(span, 2),
                "frames_per_second": round((len(window) - 1) / span, 3) if span > 0 else 0.0,
                "edit_to_pixel_ms": None if spread is None else asdict(spread),
                "edit_to_pixel_max_ms": None if spread is None else spread.max, "edits_sent": len(sent_at), "edits_unseen": len(sent_at) - len(latencies),
                "edit_every_s": edit_every, "rss_mb": rss,
                "longest_gap_s": round(float(gaps.max()), 3) if len(gaps) else None,
                "capture_hz": last.get("capture_hz"), "capture_age_s": last.get("capture_age_s"),
                "latency_ms": last.get("latency_ms"), "last_frame_stages_ms": last.get("stages_ms"),
                "last_capture_ms": last.get("capture_ms"), "cores_busy": last.get("cores_busy")}


def measure(scene, loop: str, args, *, seconds: float | None = None, edit_every: float = EDIT_EVERY_S) -> dict:
    """Run a session of ``scene`` with ``loop`` and watch its page for ``seconds`` (default ``args.seconds``)."""
    import uvicorn

    from lftransfer.app.viewer.command import open_session
    from lftransfer.app.viewer.server import make_app

    session = open_session(scene, rig_model=args.rig_model, calibration=args.calibration, loop=loop,
                           out=Path("/tmp/lft-live-fps"))
    server = uvicorn.Server(uvicorn.Config(make_app(session), host="127.0.0.1", port=args.port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.1)
    try:
        watched = asyncio.run(_watch(f"ws://127.0.0.1:{args.port}/ws", args.seconds if seconds is None else seconds,
                                     list(scene.synthetic[0].translate), edit_every))
        # where the simulated rig rendered: its own process (lftransfer.sim.process) or this one
        return {**watched, "simulator": "process" if hasattr(session.live.rig, "cpu_seconds") else "thread"}
    finally:
        server.should_exit = True
        thread.join(120)


def main() -> None:
    from lftransfer.app.cli.common import load

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", type=Path, default=None)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--loop", default="both", choices=("both", *LIVE_LOOPS))
    parser.add_argument("--calibration", type=Path, default=None)
    parser.add_argument("--rig-model", default=DEFAULT_RIG_MODEL, choices=RIG_MODELS)
    parser.add_argument("--port", type=int, default=8787)
    parser.add_argument("--edit-every", type=float, default=EDIT_EVERY_S,
                        help="seconds between the dragged slider's edits (a browser sends one per animation frame, "
                             "1/60 s; the page renders at most one frame per edit or capture)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    scene = load(args.scene, args.quick)
    loops = LIVE_LOOPS if args.loop == "both" else (args.loop,)
    result = {"scene": str(scene.source), "quick": args.quick, "view": list(scene.view.resolution),
              "lf_camera": list(scene.rig.lf_camera), "seconds": args.seconds, "rig_model": args.rig_model,
              "calibration": str(args.calibration) if args.calibration else None,
              "machine": {"cpus": os.cpu_count(), "load_average": [round(x, 2) for x in os.getloadavg()]},
              "loops": {loop: measure(scene, loop, args, edit_every=args.edit_every) for loop in loops}}
    report(result, args.json)


def report(result: dict, path: Path | None) -> None:
    """Print the result as JSON and write it to ``path`` (atomically) when given."""
    from lftransfer.imageio_utils import write_json

    print(json.dumps(result, indent=2))
    if path is not None:
        write_json(path, result)


if __name__ == "__main__":
    main()
