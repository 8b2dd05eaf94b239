"""Reading the product's JSON / TOML files into their pydantic models, with errors that name the file,
the field and the reason.

``read_model(Model, path)`` parses ``.json`` (or ``.toml``) and validates it; any problem becomes one
:class:`FileFormatError` whose message lists every fault as ``FILE: FIELD: REASON`` (fields in dotted
form with list indices, ``intersections[1].stop_line_m``), or ``FILE: line L column C: REASON`` for a
syntax error. Nothing here writes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

M = TypeVar("M", bound=BaseModel)


class FileFormatError(ValueError):
    """A corridor or plan file that cannot be used; ``str()`` names the file, the field and the reason."""

    def __init__(self, source: str, problems: list[str]) -> None:
        self.source = source
        self.problems = problems
        super().__init__("\n".join(f"{source}: {p}" for p in problems))


def field_path(loc: tuple) -> str:
    """``('intersections', 1, 'stop_line_m')`` -> ``'intersections[1].stop_line_m'``; ``()`` -> ``'(file)'``.

    Examples
    --------
    >>> field_path(("intersections", 1, "stop_line_m"))
    'intersections[1].stop_line_m'
    """
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("function-after", "function-before", "function-plain") or str(part).startswith("function-"):
            continue
        else:
            out += f".{part}" if out else str(part)
    return out or "(file)"


def problems_of(exc: ValidationError) -> list[str]:
    """One ``FIELD: REASON`` line per pydantic error ("Value error, " prefixes dropped)."""
    out = []
    for err in exc.errors(include_url=False):
        msg = str(err["msg"]).removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown field (a typo, or a field of another schema version?)"
        elif err["type"] == "missing":
            msg = "required field missing"
        out.append(f"{field_path(tuple(err['loc']))}: {msg}")
    return out


def parse_text(text: str, source: str, toml: bool = False) -> dict:
    """The JSON (or TOML) document in ``text`` as a dict; syntax errors name the line and column."""
    try:
        data = tomllib.loads(text) if toml else json.loads(text)
    except json.JSONDecodeError as exc:
        raise FileFormatError(source, [f"line {exc.lineno} column {exc.colno}: not valid JSON ({exc.msg})"]) from None
    except tomllib.TOMLDecodeError as exc:
        raise FileFormatError(source, [f"not valid TOML ({exc})"]) from None
    if not isinstance(data, dict):
        raise FileFormatError(source, [f"(file): expected an object at the top level, got {type(data).__name__}"])
    return data


def validate(model: type[M], data: dict, source: str) -> M:
    """``model.model_validate(data)`` with the errors turned into a :class:`FileFormatError` for ``source``."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise FileFormatError(source, problems_of(exc)) from None


def read_document(path: str | Path) -> dict:
    """Parse a ``.json`` or ``.toml`` file into a dict (errors name the file)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FileFormatError(str(path), [f"cannot read ({exc.strerror or exc})"]) from None
    return parse_text(text, str(path), toml=path.suffix.lower() == ".toml")


def read_model(model: type[M], path: str | Path) -> M:
    """Read and validate ``path`` as ``model`` (see the module docstring)."""
    return validate(model, read_document(path), str(path))
