"""The corpus's cases of receivers whose plane the light crosses, and penumbrae that overlap."""

from __future__ import annotations

from wsoft.stages.adversarial.common import Case

CASES: list[Case] = []
BASES: dict = {}
