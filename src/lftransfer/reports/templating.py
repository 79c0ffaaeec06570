"""The reports' jinja2 templates (``reports/templates``: ``base.html``, ``macros.html`` and one page per report).

Autoescaping is on for every template: values are text, never markup. Two filters format numbers: ``num``
(``{{ x | num(".3g") }}``, "n/a" for NaN, None or anything that is not a number) and ``vec`` (``(a, b, c)``).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import jinja2
import numpy as np

__all__ = ["environment"]


@functools.cache
def environment() -> jinja2.Environment:
    """The reports' templates, autoescaped, with the filters ``num`` and ``vec``."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
                             autoescape=jinja2.select_autoescape(["html", "j2"]), trim_blocks=True,
                             lstrip_blocks=True)
    env.filters.update(num=_num, vec=_vec)
    return env


def _num(v, fmt: str) -> str:
    """A number formatted, or "n/a" for NaN, None or anything not a number (the templates' ``num`` filter)."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return "n/a"
    return format(v, fmt) if math.isfinite(v) else "n/a"


def _vec(values, fmt: str) -> str:
    """Numbers formatted as ``(a, b, c)`` (the templates' ``vec`` filter)."""
    return "(" + ", ".join(_num(v, fmt) for v in np.ravel(values)) + ")"
