"""The corpus's cases of animation a sequence must follow: splines, instances under an animated light, point velocities."""

from __future__ import annotations

from wsoft.stages.adversarial.common import Case

CASES: list[Case] = []
BASES: dict = {}
