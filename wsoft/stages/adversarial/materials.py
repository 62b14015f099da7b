"""The corpus's cases of material bindings and purposes: full-purpose bindings, render settings whose purposes leave nothing."""

from __future__ import annotations

from wsoft.stages.adversarial.common import Case

CASES: list[Case] = []
BASES: dict = {}
