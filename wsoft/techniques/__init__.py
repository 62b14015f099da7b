"""Techniques by name. Each module declares its parameters, reads and writes."""

from __future__ import annotations

from wsoft.errors import ParameterError
from wsoft.techniques.base import Technique
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


__all__ = ["TECHNIQUES", "Technique", "create", "get_technique"]
