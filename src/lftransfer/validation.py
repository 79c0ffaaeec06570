"""One wording for every validated file (scene files, rig files): a pydantic error as one line that names the file,
the field path and what was expected, e.g. ``scene.toml: real[0].material.roughness: Input should be ...``."""

from __future__ import annotations

from typing import Callable

from pydantic import BaseModel, ValidationError

__all__ = ["field_path", "validation_message"]

# pydantic loc entries that name a validator or a union member, not a field of the file
_NOT_FIELDS = ("function-", "list[", "union[")
_TYPE_NAMES = ("int", "str", "float", "constrained-int", "constrained-float")


def field_path(loc: tuple, root: str, is_tag: Callable[[tuple, int], bool] | None = None) -> str:
    """``("real", 0, "material", "roughness")`` -> ``"real[0].material.roughness"``; ``root`` for an empty path.

    Args:
        loc: pydantic's error location.
        root: what an empty path is called (``"<scene>"``, ``"<rig>"``).
        is_tag: whether ``loc[i]`` is a discriminated union's tag rather than a field (left out).
    """
    parts: list[str] = []
    for i, item in enumerate(loc):
        if isinstance(item, int):
            parts.append(f"[{item}]")
            continue
        if (is_tag and is_tag(loc, i)) or item.startswith(_NOT_FIELDS) or item in _TYPE_NAMES:
            continue
        parts.append(("." if parts else "") + item)
    return "".join(parts) or root


def _describe(err: dict, root: str, is_tag, extra) -> str:
    msg = err.get("msg", "invalid")
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    if err.get("type") == "extra_forbidden":
        msg = "unknown key (not a field of this table)"
    elif err.get("type") == "missing":
        msg = "required field is missing"
    text = f"{field_path(tuple(err.get('loc', ())), root, is_tag)}: {msg}" + (extra(err) if extra else "")
    if err.get("type") not in ("value_error", "missing", "assertion_error") and "input" in err:
        found = err["input"]
        if not isinstance(found, (dict, BaseModel)):
            text += f", found {found!r}"
    return text


def validation_message(name: str, exc: ValidationError, *, root: str,
                       is_tag: Callable[[tuple, int], bool] | None = None,
                       extra: Callable[[dict], str] | None = None, first_per_field: bool = False) -> str:
    """The first error, and up to three more, as one line.

    Args:
        name: the file's name.
        exc: the validation error.
        root: what an empty field path is called.
        is_tag: see :func:`field_path`.
        extra: more words for an error (e.g. the unknown tag of a discriminated union).
        first_per_field: keep one error per field (a plain union reports one error per member).
    """
    errors = exc.errors(include_url=False)
    if first_per_field:
        seen: dict[str, dict] = {}
        for e in errors:
            seen.setdefault(field_path(tuple(e.get("loc", ())), root, is_tag), e)
        errors = list(seen.values())
    text = f"{name}: {_describe(errors[0], root, is_tag, extra)}"
    if len(errors) > 1:
        text += f" (and {len(errors) - 1} more: " + "; ".join(_describe(e, root, is_tag, extra) for e in errors[1:4])
        text += "; ..." if len(errors) > 4 else ""
        text += ")"
    return text
