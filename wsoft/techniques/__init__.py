"""Techniques by name. Each module declares its parameters, what it reads and writes, what it
supports and its quality knobs; :func:`markdown_table` renders the README's table from them."""

from __future__ import annotations

import dataclasses

from wsoft.errors import ParameterError
from wsoft.techniques.base import Quality, Technique, Tolerance
from wsoft.techniques.esm import ESM
from wsoft.techniques.essm import ESSM
from wsoft.techniques.hard import Hard
from wsoft.techniques.pcf import PCF
from wsoft.techniques.pcss import PCSS
from wsoft.techniques.reference import Reference
from wsoft.techniques.salzman import Salzman
from wsoft.techniques.ssm import SSM
from wsoft.techniques.vsm import VSM
from wsoft.techniques.vssm import VSSM

TECHNIQUES: dict[str, type[Technique]] = {t.name: t for t in (Reference, Hard, PCF, PCSS, VSM, ESM, Salzman, ESSM, VSSM, SSM)}


def get_technique(name: str) -> type[Technique]:
    try:
        return TECHNIQUES[name]
    except KeyError:
        raise ParameterError(f"unknown technique {name!r}; techniques: {', '.join(sorted(TECHNIQUES))}") from None


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
    for name in ["reference"] + sorted(n for n in TECHNIQUES if n != "reference"):
        cls = TECHNIQUES[name]
        params = ", ".join(f"`{f.name}` ({f.default!r})" for f in dataclasses.fields(cls.Params))
        quality = "; ".join(f"`{q.param}`: {', '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in q.values)}" for q in cls.quality) or "-"
        rows.append(f"| `{name}` | {cls.summary} | {params} | {quality} |")
    return "\n".join(rows)


for _cls in TECHNIQUES.values():  # the class docstring is the manual: append the parameter table
    _cls.__doc__ = (_cls.__doc__ or "").rstrip() + "\n\nParameters:\n\n" + parameter_table(_cls) + "\n"

__all__ = ["TECHNIQUES", "Quality", "Technique", "Tolerance", "create", "get_technique", "markdown_table", "parameter_table"]
