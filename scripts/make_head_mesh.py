"""Write the head-like mesh of the built-in ``fig5`` scene (src/lftransfer/scenes/meshes/head.obj).

A stand-in for the paper's real head: a cranium, a jaw, a nose, two ears and a neck, each an ellipsoid or a
cylinder made with trimesh and joined into one triangle mesh (overlapping closed shells; hidden faces inside do
not show). The face looks along -z (towards the lens array when the mesh stands in the real half-space), +y is
up, metres. Deterministic: running it again writes the same file.

Usage: python scripts/make_head_mesh.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

OUT = Path(__file__).resolve().parents[1] / "src" / "lftransfer" / "scenes" / "meshes" / "head.obj"


def ellipsoid(radii, centre, subdivisions: int = 3) -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    mesh.apply_scale(radii)
    mesh.apply_translation(centre)
    return mesh


def head() -> trimesh.Trimesh:
    parts = [
        ellipsoid((0.060, 0.075, 0.070), (0.0, 0.010, 0.0)),          # cranium
        ellipsoid((0.046, 0.042, 0.052), (0.0, -0.035, -0.014)),      # jaw and cheeks
        ellipsoid((0.010, 0.019, 0.015), (0.0, -0.006, -0.066), 2),   # nose
        ellipsoid((0.024, 0.010, 0.010), (0.0, 0.028, -0.060), 2),    # brow
        ellipsoid((0.009, 0.021, 0.013), (0.061, 0.000, 0.004), 2),   # ears
        ellipsoid((0.009, 0.021, 0.013), (-0.061, 0.000, 0.004), 2),
    ]
    neck = trimesh.creation.cylinder(radius=0.029, height=0.06, sections=48)
    neck.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    neck.apply_translation((0.0, -0.085, 0.012))
    parts.append(neck)
    return trimesh.util.concatenate(parts)


def main() -> None:
    mesh = head()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    lines = ["# head-like mesh of the fig5 scene, written by scripts/make_head_mesh.py (metres, face towards -z)"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    OUT.write_text("\n".join(lines) + "\n")
    lo, hi = mesh.bounds
    print(f"{OUT}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, bounds {lo.round(3)} .. {hi.round(3)}")


if __name__ == "__main__":
    main()
