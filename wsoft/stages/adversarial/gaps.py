"""The corpus's cases of surfaces and occluders a hair's breadth apart: a plate just above the ground, an occluder just under the light."""

from __future__ import annotations

from wsoft.stages.adversarial.common import Case

CASES: list[Case] = []
BASES: dict = {}
