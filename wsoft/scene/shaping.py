"""A light's ``UsdLux.ShapingAPI`` inputs (:class:`Shaping`), as :func:`~wsoft.scene.usd_lights.read_shaping`
reads them; :func:`~wsoft.lightspace.light.shaping_weight` applies them (docs/usd.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Shaping:
    """The shaping of a local light's emission about its primary axis, its local −Z. A distant
    light's is always the default (no shaping)."""

    cone_deg: float = 180.0
    """``shaping:cone:angle``: degrees off the axis past which the light emits nothing (180: no cone)."""
    softness: float = 0.0
    """``shaping:cone:softness`` in [0, 1]: the share of the cone, from its edge inward, over which
    emission rises smoothly (smoothstep in the cosine) from 0 (0: a hard edge)."""
    focus: float = 0.0
    """``shaping:focus``: emission off axis times ``cos^focus`` (0: no focus)."""
    focus_tint: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """``shaping:focusTint``: the colour the focus fades toward off axis (black: a plain fade)."""

    @property
    def coned(self) -> bool:
        """Does a cone narrower than 180 degrees cut the emission off?"""
        return self.cone_deg < 180.0

    @property
    def shaped(self) -> bool:
        """Does a cone or a focus shape the emission?"""
        return self.coned or self.focus > 0.0
