"""Techniques by name. Each module declares its parameters, what it reads and writes, what it
supports and its quality knobs; :func:`markdown_table` renders the README's table from them.

:data:`NAMES` lists the techniques without importing them; ``TECHNIQUES`` (name -> class) imports
the technique modules, and with them Warp, at first use (``wsoft --help`` needs only the names).
"""

from __future__ import annotations

import dataclasses
import importlib

from wsoft.errors import ParameterError
from wsoft.techniques.base import Quality, Technique, Tolerance

# name -> (module, class), in the order of TECHNIQUES
_REGISTRY = {
    "reference": ("wsoft.techniques.reference", "Reference"),
    "hard": ("wsoft.techniques.hard", "Hard"),
    "pcf": ("wsoft.techniques.pcf", "PCF"),
    "pcss": ("wsoft.techniques.pcss", "PCSS"),
    "vsm": ("wsoft.techniques.vsm", "VSM"),
    "esm": ("wsoft.techniques.esm", "ESM"),
    "salzman": ("wsoft.techniques.salzman", "Salzman"),
    "essm": ("wsoft.techniques.essm", "ESSM"),
    "vssm": ("wsoft.techniques.vssm", "VSSM"),
    "ssm": ("wsoft.techniques.ssm", "SSM"),
    "izb": ("wsoft.techniques.izb", "IZB"),
    "dcs": ("wsoft.techniques.dcs", "DCS"),
    "pwedge": ("wsoft.techniques.pwedge", "PWedge"),
}
NAMES: tuple[str, ...] = tuple(_REGISTRY)
_TECHNIQUES: dict[str, type[Technique]] | None = None


def _techniques() -> dict[str, type[Technique]]:
    """``TECHNIQUES``, imported once; each class docstring gets its parameter table (the manual)."""
    global _TECHNIQUES
    if _TECHNIQUES is None:
        found = {}
        for name, (module, cls_name) in _REGISTRY.items():
            cls = getattr(importlib.import_module(module), cls_name)
            if cls.name != name:
                raise RuntimeError(f"{module}.{cls_name} is named {cls.name!r}, registered as {name!r}")
            if "\n\nParameters:\n\n" not in (cls.__doc__ or ""):
                cls.__doc__ = (cls.__doc__ or "").rstrip() + "\n\nParameters:\n\n" + parameter_table(cls) + "\n"
            found[name] = cls
        _TECHNIQUES = found
    return _TECHNIQUES


def __getattr__(name: str):
    if name == "TECHNIQUES":
        globals()["TECHNIQUES"] = _techniques()
        return globals()["TECHNIQUES"]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def get_technique(name: str) -> type[Technique]:
    techniques = _techniques()
    try:
        return techniques[name]
    except KeyError:
        raise ParameterError(f"unknown technique {name!r}; techniques: {', '.join(sorted(techniques))}") from None


def create(name: str, params: dict | None = None) -> Technique:
    """A technique instance from its name and a dict of parameters (unknown keys are errors)."""
    cls = get_technique(name)
    return cls(cls.make_params(params))


def parameter_table(cls: type[Technique]) -> str:
    """The technique's parameters as a markdown table (name, type, default, range, meaning)."""
    rows = ["| parameter | type | default | range | meaning |", "|---|---|---|---|---|"]
    for p in cls.describe()["parameters"]:
        rows.append(f"| `{p['name']}` | {p['type']} | {p['default']!r} | {p['range']} | {p['meaning']} |")
    return "\n".join(rows)


def markdown_table() -> str:
    """The README's technique table, from the code: name, summary, parameters with defaults, quality knobs."""
    rows = ["| name | what | parameters (default) | quality knobs (sweep values) |", "|---|---|---|---|"]
    techniques = _techniques()
    for name in ["reference"] + sorted(n for n in techniques if n != "reference"):
        cls = techniques[name]
        params = ", ".join(f"`{f.name}` ({f.default!r})" for f in dataclasses.fields(cls.Params))
        quality = "; ".join(f"`{q.param}`: {', '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in q.values)}" for q in cls.quality) or "-"
        rows.append(f"| `{name}` | {cls.summary} | {params} | {quality} |")
    return "\n".join(rows)


__all__ = ["NAMES", "TECHNIQUES", "Quality", "Technique", "Tolerance", "create", "get_technique", "markdown_table", "parameter_table"]
