"""The point light step alone, over hidden truths: how far from the real light it puts it.

For each scene and seed, opens the simulated rig of that hidden truth (the first interface's, for a scene of
several), gives the step the true rig model (so that only the step's own error remains: the chessboards' poses and
the fit), runs :func:`~lftransfer.calibration.light.calibrate_light` for every point light and prints how far each
lands from where it really stands, and each board's tilt as its chessboard measures it against how the simulated
operator really held it. The whole calibration's light error is in ``lft calibrate seeds`` and the stored runs.

Usage:
    python scripts/light_step_seeds.py [SCENE ...] [--seeds 0,1,2,3] [--full] [--json OUT]

``--full``: the scene's own resolution (default: ``--quick``'s quarter resolution).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def measure(name: str, seed: int, full: bool) -> dict:
    """One scene and hidden truth: per light the error (mm) and per board its measured tilt error (degrees)."""
    from lftransfer.calibration.interfaces import interface_scene
    from lftransfer.calibration.light import calibrate_light
    from lftransfer.scenes import builtin_scene, load_scene, quick_scene
    from lftransfer.sim.oracle import open_simulated_interfaces, open_simulated_rig
    from lftransfer.sim.truth import hidden_world

    scene = load_scene(builtin_scene(name))
    scene = scene if full else quick_scene(scene)
    world, _ = hidden_world(scene, seed)
    if scene.interfaces:
        rigs, oracle = open_simulated_interfaces(scene, seed)
        rig, model, measured = rigs[0], oracle.models[0], interface_scene(scene.synthetic_part(), 0)
    else:
        rig, oracle = open_simulated_rig(scene, seed)
        model, measured = oracle.model, scene.synthetic_part()
    out = []
    for k in range(len(measured.lights)):
        start = time.time()
        fit, diag = calibrate_light(rig, model, measured, light=k)
        held = rig.boards_held[-len(diag["boards"]):]
        tilts = []
        for board, m in zip(diag["boards"], held):
            n = m[:3, 2] / np.linalg.norm(m[:3, 2])
            tilts.append(float(np.degrees(np.arccos(min(1.0, abs(float(np.asarray(board["normal"]) @ n)))))))
        error = 1000 * float(np.linalg.norm(np.asarray(fit.position) - np.asarray(world.lights[k].position)))
        out.append({"light": k, "error_mm": error, "board_tilt_error_deg": tilts, "seconds": time.time() - start})
    return {"scene": name, "seed": seed, "full": full, "lights": out}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=["fig4", "corner", "enclosure"])
    parser.add_argument("--seeds", default="0,1,2,3")
    parser.add_argument("--full", action="store_true")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    rows = []
    for name in args.scenes:
        errors = []
        for seed in (int(s) for s in args.seeds.split(",")):
            row = measure(name, seed, args.full)
            rows.append(row)
            for light in row["lights"]:
                errors.append(light["error_mm"])
                tilts = ", ".join(f"{t:.2f}" for t in light["board_tilt_error_deg"])
                print(f"{name} seed {seed} light {light['light']}: {light['error_mm']:.2f} mm "
                      f"(boards' tilt errors {tilts} degree; {light['seconds']:.0f} s)", flush=True)
        print(f"{name}: RMS {float(np.sqrt(np.mean(np.square(errors)))):.2f} mm, worst {max(errors):.2f} mm")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
