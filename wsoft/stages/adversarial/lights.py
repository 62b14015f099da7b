"""The corpus's cases of what a light emits and how wide it is: a wide distant light, intensity, exposure and colour in the shaded image."""

from __future__ import annotations

from wsoft.stages.adversarial.common import Case

CASES: list[Case] = []
BASES: dict = {}
