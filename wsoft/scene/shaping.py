"""A light's ``UsdLux.ShapingAPI`` inputs (:class:`Shaping`), as :func:`~wsoft.scene.usd_lights.read_shaping`
reads them; :func:`~wsoft.lightspace.light.shaping_weight` applies them (docs/usd.md)."""

from __future__ import annotations

from dataclasses import dataclass

from wsoft.scene.ies import IesProfile


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
    ies: IesProfile | None = None
    """``shaping:ies:file``'s profile (None: no profile). Its vertical angle 0 is the light's −Z, its
    horizontal angle 0 the light's +X and 90 its +Y. The cone neither clips nor rescales it: the
    emission is the profile's factor times the cone's, softness's and focus's."""
    ies_path: str = ""
    """The profile's file as the stage resolved it (for messages and ``plan``)."""
    ies_angle_scale: float = 0.0
    """``shaping:ies:angleScale`` (> -1): the profile is read at ``(theta - 180) / (1 + angleScale) + 180``
    degrees for the angle ``theta`` off −Z (:func:`~wsoft.scene.ies.ies_angle`)."""
    ies_normalize: bool = False
    """``shaping:ies:normalize``: on, the profile is divided by its mean intensity over the sphere (the
    light emits the same flux as without the profile, as UsdLux documents it: "preserving the overall
    energy output"); off, by its peak (1 along its brightest direction)."""

    @property
    def coned(self) -> bool:
        """Does a cone narrower than 180 degrees cut the emission off?"""
        return self.cone_deg < 180.0

    @property
    def shaped(self) -> bool:
        """Does a cone, a focus or an IES profile shape the emission?"""
        return self.coned or self.focus > 0.0 or self.ies is not None

    def ies_divisor(self) -> float:
        """What the profile's candela values are divided by (:attr:`ies_normalize`; 1 without one)."""
        if self.ies is None:
            return 1.0
        return self.ies.mean_intensity() if self.ies_normalize else self.ies.peak()
