"""One wording for every validated file (scene files, rig files, calibration files): a pydantic error as one line
that names the file, the field path and what was expected, e.g.
``scene.toml: real[0].material.roughness: Input should be ...``; and one way to read such a file's text: UTF-8,
a leading byte order mark accepted, anything else one line naming the file, where the bad byte is and what was
expected (``scene.toml: <encoding>: not UTF-8 text: byte 0xe9 on line 3 ...``)."""

from __future__ import annotations

import difflib
import json
import numbers
import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Callable

from pydantic import BaseModel, BeforeValidator, ValidationError

__all__ = ["STRICT_NUMBER", "field_path", "keys_at", "read_json", "read_text", "read_toml", "strict_number",
           "validation_message"]

# pydantic loc entries that name a validator or a union member, not a field of the file
_NOT_FIELDS = ("function-", "list[", "union[")
_TYPE_NAMES = ("int", "str", "float", "constrained-int", "constrained-float")
_PLAIN_KEY = re.compile(r"[A-Za-z0-9_\-]+")


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
        if not _PLAIN_KEY.fullmatch(item):               # a key with blanks, line breaks, dots: quoted, one line
            parts.append(f"[{item!r}]")
            continue
        parts.append(("." if parts else "") + item)
    return "".join(parts) or root


def _members(kind) -> list:
    """The types a field's annotation may hold: unions and ``Annotated`` opened, ``list[X]`` kept whole."""
    origin = typing.get_origin(kind)
    if origin is typing.Annotated:
        return _members(typing.get_args(kind)[0])
    if origin in (typing.Union, types.UnionType):
        return [m for arg in typing.get_args(kind) for m in _members(arg)]
    return [kind]


def _models(kinds: list) -> list[type[BaseModel]]:
    return [k for k in kinds if isinstance(k, type) and issubclass(k, BaseModel)]


def keys_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """The keys a table at ``loc`` may have (``loc`` ends with the key looked up, as pydantic's does): the fields,
    and their aliases, of every model the annotations along ``loc`` allow; a union's tag, which names no field,
    keeps every member. Empty where ``loc`` leaves the models."""
    kinds: list = [model]
    for item in loc[:-1]:
        following: list = []
        for kind in kinds:
            if isinstance(item, int):
                if typing.get_origin(kind) in (list, tuple):
                    following += [m for arg in typing.get_args(kind) if arg is not Ellipsis for m in _members(arg)]
                continue
            for m in _models([kind]):
                spec = m.model_fields.get(item) or next(
                    (f for f in m.model_fields.values() if item in _aliases(f)), None)
                if spec is not None:
                    following += _members(spec.annotation)
        if isinstance(item, int):
            kinds = following
        elif following:
            kinds = following
        # else: a union's tag, which names no field: every member stays
    return sorted({key for m in _models(kinds) for name, f in m.model_fields.items() for key in (name, *_aliases(f))})


def _aliases(spec) -> list[str]:
    alias = spec.validation_alias
    if isinstance(alias, str):
        return [alias]
    return [c for c in getattr(alias, "choices", ()) if isinstance(c, str)]


def _object_name(loc: tuple, data) -> str | None:
    """The ``name`` of the innermost list entry along ``loc`` in the file's data (an object's name), or None."""
    name, node = None, data
    for item in loc[:-1]:
        try:
            node = node[item]
        except (KeyError, IndexError, TypeError):
            break
        if isinstance(item, int) and isinstance(node, dict) and isinstance(node.get("name"), str):
            name = node["name"]
    return name


def _describe(err: dict, root: str, is_tag, extra, model=None, data=None) -> str:
    msg = err.get("msg", "invalid")
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    loc = tuple(err.get("loc", ()))
    if err.get("type") == "extra_forbidden":
        msg = "unknown key (not a field of this table"
        close = difflib.get_close_matches(str(loc[-1]), keys_at(model, loc), n=1, cutoff=0.6) \
            if model is not None and loc else []
        msg += f"; did you mean {close[0]!r}?)" if close else ")"
    elif err.get("type") == "missing":
        msg = "required field is missing"
    where = field_path(loc, root, is_tag)
    name = _object_name(loc, data) if data is not None else None
    if name is not None:
        where += f" (of {name!r})"
    text = f"{where}: {msg}" + (extra(err) if extra else "")
    if err.get("type") not in ("value_error", "missing", "assertion_error") and "input" in err:
        found = err["input"]
        if not isinstance(found, (dict, BaseModel)):
            text += f", found {found!r}"
    return text


def validation_message(name: str, exc: ValidationError, *, root: str,
                       is_tag: Callable[[tuple, int], bool] | None = None,
                       extra: Callable[[dict], str] | None = None, first_per_field: bool = False,
                       model: type[BaseModel] | None = None, data: Any = None) -> str:
    """The first error, and up to three more, as one line.

    Args:
        name: the file's name.
        exc: the validation error.
        root: what an empty field path is called.
        is_tag: see :func:`field_path`.
        extra: more words for an error (e.g. the unknown tag of a discriminated union).
        first_per_field: keep one error per field (a plain union reports one error per member).
        model: the model the file was validated against: an unknown key then gets the closest key of its table
            (:func:`keys_at`, ``did you mean 'albedo'?``).
        data: the file's data: a field inside a list entry with a ``name`` then says whose it is
            (``real[0].colour (of 'post')``).
    """
    errors = exc.errors(include_url=False)
    if first_per_field:
        seen: dict[str, dict] = {}
        for e in errors:
            seen.setdefault(field_path(tuple(e.get("loc", ())), root, is_tag), e)
        errors = list(seen.values())
    text = f"{name}: {_describe(errors[0], root, is_tag, extra, model, data)}"
    if len(errors) > 1:
        text += f" (and {len(errors) - 1} more: " + "; ".join(_describe(e, root, is_tag, extra, model, data)
                                                             for e in errors[1:4])
        text += "; ..." if len(errors) > 4 else ""
        text += ")"
    return text


def read_text(path: str | Path, what: str, error: type[Exception]) -> str:
    """A text file's contents, decoded as UTF-8 (a leading byte order mark is dropped).

    Args:
        path: the file.
        what: what the file is, for messages (``"scene file"``).
        error: the exception class to raise (the caller's own, e.g. ``SceneError``).

    Raises:
        error: the file cannot be read (``<path>: cannot read the <what>: <reason>``) or is not UTF-8 text
            (``<path>: <encoding>: not UTF-8 text: byte 0x.. on line N, column C; save it as UTF-8``).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise error(f"{path}: <encoding>: not UTF-8 text: byte 0x{data[exc.start]:02x} on line {line}, column "
                    f"{column}; save the {what} as UTF-8") from None


def read_toml(path: str | Path, what: str, error: type[Exception]) -> dict:
    """A TOML file's tables (read with :func:`read_text`).

    Raises:
        error: unreadable, not UTF-8, or malformed TOML (``<path>: <toml>: malformed TOML: <where and why>``).
    """
    text = read_text(path, what, error)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: <toml>: malformed TOML: {exc}") from None
    except RecursionError:
        raise error(f"{path}: <toml>: malformed TOML: nested too deeply") from None


def read_json(path: str | Path, what: str, error: type[Exception]) -> object:
    """A JSON file's value (read with :func:`read_text`; ``NaN`` and ``Infinity`` are read as floats).

    Raises:
        error: unreadable, not UTF-8, or malformed JSON (``<path>: <json>: malformed JSON: <why> (line L, column
            C)``).
    """
    text = read_text(path, what, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{path}: <json>: malformed JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except RecursionError:
        raise error(f"{path}: <json>: malformed JSON: nested too deeply") from None


def strict_number(value: Any) -> Any:
    """Reject strings and booleans where a number is expected (pydantic's lax mode would convert them)."""
    if isinstance(value, (str, bool)):
        raise ValueError(f"expected a number, found {type(value).__name__} {value!r}")
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return value


STRICT_NUMBER = BeforeValidator(strict_number)     # for ``Annotated[float, STRICT_NUMBER, ...]`` fields
