"""``lft new scene PATH``: a commented scene file to start from (two real objects, two synthetic ones, a light)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape

from lftransfer.app.cli.common import command, sub_app
from lftransfer.app.cli.options import flag
from lftransfer.app.terminal import fail

new_app = sub_app(name="new", help="Files to start from: a commented scene (lft new scene PATH).")

TEMPLATE = Path(__file__).resolve().parents[2] / "scenes" / "templates" / "scene.toml"


@command(new_app, "scene")
def scene(path: Annotated[Path, typer.Argument(metavar="PATH.toml", help="Where the scene file goes.")],
          force: Annotated[bool, flag("--force", "Write over a file that is there.")] = False) -> None:
    """Write a commented scene file (two real objects, two synthetic ones, one point light; every field explained
    or pointed to docs/scene-format.md) that lft run accepts as it is."""
    from lftransfer.imageio_utils import write_text
    from lftransfer.scenes import load_scene

    if path.suffix != ".toml":
        fail(f"{path}: expected a .toml file name")
    if path.exists() and not force:
        fail(f"{path}: exists already; --force writes over it")
    if not path.parent.is_dir():
        fail(f"{path}: the folder {path.parent} does not exist")
    write_text(path, TEMPLATE.read_text(encoding="utf-8"))
    load_scene(path)                                   # what lft run will read, checked now
    Console().print(escape(f"wrote {path}; try: lft run {path} --quick"), soft_wrap=True, highlight=False)
