"""Write a test light field of known disparity in the 4D light field benchmark's layout: a textured square in
front of a textured plane (lftransfer.lightfield.view_grid.two_layer_grid), N x N views, with its true disparity.

    python scripts/make_two_layer_light_field.py OUT [--views 9] [--size 512]
    lft depth OUT --truth OUT/gt_disp_lowres.pfm --out OUT/estimate
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lftransfer.lightfield.view_grid import two_layer_grid, write_pfm, write_view_grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--views", type=int, default=9, help="views per side (odd)")
    parser.add_argument("--size", type=int, default=512, help="pixels per side of each view")
    args = parser.parse_args()
    grid, truth = two_layer_grid(args.views, args.size)
    write_view_grid(args.out, grid)
    write_pfm(args.out / "gt_disp_lowres.pfm", truth)
    print(f"wrote {args.views} x {args.views} views of {args.size} x {args.size} and gt_disp_lowres.pfm to {args.out}")


if __name__ == "__main__":
    main()
