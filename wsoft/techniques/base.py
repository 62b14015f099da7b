"""What every technique is: parameters (a frozen dataclass), what it reads, what it writes,
and the passes it adds to a frame graph for one light.

Copy ``techniques/hard.py`` to add a technique: declare ``Params``, ``reads``/``writes``,
and implement :meth:`Technique.add_passes`, which registers passes through the
:class:`~wsoft.render.RenderContext` (scene arrays, G-buffer, light depth maps, the
scene's triangles and textures) and returns the key of the visibility it writes.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, ClassVar

from wsoft.errors import ParameterError


def param(default, help: str, **kw):
    """A parameter field with its meaning (shown by ``wsoft techniques``)."""
    return dataclasses.field(default=default, metadata={"help": help, **kw})


def _convert(name: str, typ, value, technique: str):
    if isinstance(typ, str):
        typ = {"int": int, "float": float, "bool": bool, "str": str}.get(typ, str)
    if isinstance(value, typ) and not (typ is int and isinstance(value, bool)):
        return value
    try:
        if typ is bool:
            if isinstance(value, str):
                low = value.strip().lower()
                if low in ("1", "true", "yes", "on"):
                    return True
                if low in ("0", "false", "no", "off"):
                    return False
                raise ValueError(value)
            if isinstance(value, (int, float)) and value in (0, 1):
                return bool(value)
            raise ValueError(value)
        if typ is int:
            f = float(value)
            if not f.is_integer():
                raise ValueError(value)
            return int(f)
        if typ is float:
            return float(value)
        return typ(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{technique}: parameter {name}={value!r} is not a valid {typ.__name__}") from None


class Technique:
    """Base class. Subclasses set the class attributes below and implement ``add_passes``."""

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    Params: ClassVar[type]
    reads: ClassVar[tuple[str, ...]] = ()
    writes: ClassVar[tuple[str, ...]] = ("visibility",)

    def __init__(self, params):
        self.params = params

    @classmethod
    def make_params(cls, values: dict[str, Any] | None = None):
        """Build ``Params`` from a dict (strings from the CLI are converted); unknown keys are errors."""
        values = dict(values or {})
        fields = {f.name: f for f in dataclasses.fields(cls.Params)}
        unknown = sorted(set(values) - set(fields))
        if unknown:
            raise ParameterError(
                f"technique {cls.name!r} has no parameter {', '.join(unknown)}; its parameters: {', '.join(fields) or 'none'}"
            )
        hints = typing.get_type_hints(cls.Params)
        conv = {k: _convert(k, hints.get(k, fields[k].type), v, cls.name) for k, v in values.items()}
        try:
            return cls.Params(**conv)
        except ValueError as exc:
            raise ParameterError(f"{cls.name}: {exc}") from None

    @classmethod
    def describe(cls) -> dict:
        hints = typing.get_type_hints(cls.Params)
        return {
            "name": cls.name,
            "summary": cls.summary,
            "reads": list(cls.reads),
            "writes": list(cls.writes),
            "parameters": [
                {"name": f.name, "type": getattr(hints.get(f.name), "__name__", str(f.type)), "default": f.default, "meaning": f.metadata.get("help", "")}
                for f in dataclasses.fields(cls.Params)
            ],
        }

    def add_passes(self, ctx, light) -> str:  # pragma: no cover - interface
        raise NotImplementedError


def check(cond: bool, msg: str):
    """Validation helper for ``Params.__post_init__``: raises ValueError (reported as a parameter error)."""
    if not cond:
        raise ValueError(msg)
