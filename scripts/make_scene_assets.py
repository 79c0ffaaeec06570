"""Write the meshes and images of the built-in ``fig6`` and ``fig1b`` scenes (src/lftransfer/scenes/).

Stand-ins for the paper's real objects and photographs, made here so that nothing is downloaded:

- ``meshes/bowl.obj``: a shiny round bowl, a closed thin shell of revolution (outer and inner spherical walls
  cut above the equator and joined by a rounded rim), 10 cm across, its foot at y = 0, opening towards +y;
- ``meshes/hand.obj``: a hand held up flat, palm towards -z: a palm and five fingers, each an ellipsoid or a
  capsule made with trimesh and joined into one triangle mesh (overlapping closed shells);
- ``textures/checker.png``: the checkered surface under the bowl (8 x 8 squares, light and dark grey);
- ``textures/photo.png``: the "photograph" of fig6 and fig1b, a painted landscape (sky, sun, hills, a lake, a
  tree) drawn with numpy: colourful and with detail at several scales, so its reflection is easy to see.

Deterministic: running it again writes the same files.

Usage: python scripts/make_scene_assets.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

SCENES = Path(__file__).resolve().parents[1] / "src" / "lftransfer" / "scenes"


def _write_obj(mesh: trimesh.Trimesh, path: Path, comment: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"# {comment}, written by scripts/make_scene_assets.py (metres)"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    path.write_text("\n".join(lines) + "\n")
    lo, hi = mesh.bounds
    print(f"{path}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, bounds {lo.round(3)} .. {hi.round(3)}")


def bowl(radius: float = 0.05, wall: float = 0.004, rim_deg: float = 125.0, sections: int = 160) -> trimesh.Trimesh:
    """A round bowl: the profile (a flat foot, the outer wall, a half-round rim, the inner wall) turned about the
    y axis. The walls are spheres of ``radius`` and ``radius - wall`` about one centre, cut ``rim_deg`` from the
    bottom (above the equator, so the bowl is widest at its middle and its outer wall faces sideways and up
    there, where it reflects the scene around it); y = 0 is the foot."""
    foot = np.radians(20.0)
    t = np.linspace(foot, np.radians(rim_deg), 64)
    drop = radius * (1 - np.cos(foot))                            # the foot's flat cut
    outer = np.stack([radius * np.sin(t), radius * (1 - np.cos(t)) - drop], 1)
    inner_r = radius - wall
    inner = np.stack([inner_r * np.sin(t[::-1]), radius - inner_r * np.cos(t[::-1]) - drop], 1)
    rim_c = 0.5 * (outer[-1] + inner[0])
    start = np.arctan2(*(outer[-1] - rim_c)[::-1])
    a = start + np.linspace(0.0, np.pi, 12)[1:-1]
    rim = rim_c + (wall / 2) * np.stack([np.cos(a), np.sin(a)], 1)
    floor = inner[-1, 1]
    profile = np.concatenate([[[0.0, 0.0]], outer, rim, inner, [[0.0, floor]]])
    mesh = trimesh.creation.revolve(profile, sections=sections)   # about the profile's y -> mesh z axis
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))   # z up -> y up
    mesh.merge_vertices()
    mesh.fix_normals()
    return mesh


def _capsule(radius: float, length: float, start, direction) -> trimesh.Trimesh:
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    mesh = trimesh.creation.capsule(height=length, radius=radius, count=[16, 16])
    mesh.apply_translation([0, 0, length / 2])                    # from its base along +z
    axis = np.cross([0, 0, 1], d)
    if np.linalg.norm(axis) > 1e-9:
        angle = np.arccos(np.clip(d[2], -1, 1))
        mesh.apply_transform(trimesh.transformations.rotation_matrix(angle, axis))
    mesh.apply_translation(start)
    return mesh


def hand() -> trimesh.Trimesh:
    """An open hand held up, fingers along +y, palm facing -z, about 18 cm tall; the wrist's end at y = 0."""
    palm = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    palm.apply_scale((0.042, 0.05, 0.014))
    palm.apply_translation((0.0, 0.075, 0.0))
    wrist = _capsule(0.022, 0.04, (0.0, 0.0, 0.003), (0, 1, 0))
    fingers = [_capsule(r, length, (x, 0.112, 0.0), (dx, 1.0, 0.0))
               for x, r, length, dx in ((-0.030, 0.0085, 0.060, -0.12), (-0.010, 0.0090, 0.072, -0.03),
                                        (0.010, 0.0090, 0.068, 0.03), (0.028, 0.0080, 0.055, 0.12))]
    thumb = _capsule(0.010, 0.055, (0.036, 0.06, -0.004), (1.0, 0.75, -0.2))
    return trimesh.util.concatenate([palm, wrist, thumb, *fingers])


def checker(size: int = 256, squares: int = 8) -> np.ndarray:
    """(size, size, 3) uint8 checkerboard, sRGB codes of 0.6 and 0.12 linear grey."""
    i = (np.arange(size) * squares // size)
    board = (i[:, None] + i[None, :]) % 2 == 0
    light, dark = _srgb(np.array(0.6)), _srgb(np.array(0.12))
    return np.repeat(np.where(board, light, dark)[..., None], 3, axis=2).astype(np.uint8)


def photo(width: int = 320, height: int = 240) -> np.ndarray:
    """(height, width, 3) uint8 sRGB: a painted landscape (linear colours composed in layers, then encoded)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    u, v = x / (width - 1), 1.0 - y / (height - 1)                # v = 1 at the top
    sky = np.stack([0.15 + 0.35 * (1 - v), 0.35 + 0.3 * (1 - v), 0.85 - 0.1 * (1 - v)], -1)
    img = sky
    sun = np.exp(-(((u - 0.72) / 0.07) ** 2 + ((v - 0.78) / 0.09) ** 2) ** 2)
    img = img + sun[..., None] * (np.array([1.0, 0.85, 0.35]) - img)
    far = 0.55 + 0.06 * np.sin(9 * u + 1.0) + 0.04 * np.sin(23 * u)
    img = np.where((v < far)[..., None], np.array([0.35, 0.38, 0.6]), img)        # far blue mountains
    near = 0.38 + 0.08 * np.sin(5 * u + 2.5) + 0.02 * np.sin(31 * u)
    img = np.where((v < near)[..., None], np.array([0.2, 0.55, 0.15]), img)       # green hills
    lake = (v < 0.22) & (np.abs(u - 0.4) < 0.35 - 0.8 * np.abs(v - 0.11))
    img = np.where(lake[..., None], np.array([0.1, 0.3, 0.75]) * (0.8 + 0.2 * np.sin(60 * v))[..., None], img)
    trunk = (np.abs(u - 0.18) < 0.012) & (v > 0.2) & (v < 0.42)
    crown = ((u - 0.18) / 0.07) ** 2 + ((v - 0.5) / 0.1) ** 2 < 1
    img = np.where(trunk[..., None], np.array([0.35, 0.2, 0.08]), img)
    img = np.where(crown[..., None], np.array([0.08, 0.35, 0.08]), img)
    return _srgb(np.clip(img, 0, 1)).astype(np.uint8)


def _srgb(linear: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes of linear values in [0, 1]."""
    c = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1 / 2.4) - 0.055)
    return np.round(255 * c)


def main() -> None:
    _write_obj(bowl(), SCENES / "meshes" / "bowl.obj", "shiny bowl of the fig6 scene, foot at y = 0, opening +y")
    _write_obj(hand(), SCENES / "meshes" / "hand.obj", "open hand of the fig1b scene, fingers +y, palm towards -z")
    for name, image in (("checker.png", checker()), ("photo.png", photo())):
        path = SCENES / "textures" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(image).save(path, optimize=True)
        print(f"{path}: {image.shape[1]} x {image.shape[0]}")


if __name__ == "__main__":
    main()
