"""The corpus's cases of what a light emits and how wide it is: a wide distant light, intensity, exposure and colour in the shaded image."""

from __future__ import annotations

import math

import numpy as np

from wsoft.stages.adversarial.checks import CENTRAL
from wsoft.stages.adversarial.common import Case, _base, _save
from wsoft.stages.builders import add_sun

CASES: list[Case] = []
BASES: dict = {}

OCCLUDER_HALF = 1.0  # the base's occluder: |x|, |y| <= 1 at z = 1


def _wide_sun(angle: float):
    def build(folder: str) -> str:
        st = _base()
        st.RemovePrim("/World/Light")
        add_sun(st, "/World/Light", angle, toward=(0.0, 0.0, 1.0))
        return _save(st, folder, f"wide_sun_{angle:g}")

    build.__doc__ = f"The base under a DistantLight of angle {angle:g} degrees straight overhead (no light of its own)."
    return build


def _cone(angle: float, n: int = 4096) -> np.ndarray:
    """``n`` unit directions evenly over the solid angle of a cone of full ``angle`` degrees about +Z
    (a sunflower pattern in cos theta and phi: uniform in solid angle, as UsdLux's cone and the reference)."""
    k = np.arange(n) + 0.5
    cos_t = 1.0 - (1.0 - math.cos(math.radians(0.5 * angle))) * k / n
    sin_t = np.sqrt(1.0 - cos_t * cos_t)
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], -1)


def cone_visible(angle: float, tol: float = 0.03):
    """A check of :func:`_wide_sun`'s stage: the mean V over the ground within ``tol`` of the mean
    exact visible fraction of the sun's cone past the occluder (of its central direction alone for
    the fixed-filter techniques of :data:`~wsoft.stages.adversarial.checks.CENTRAL`)."""

    def check(ch, base=None, technique="") -> str | None:
        g = (ch["A"] > 0) & (np.abs(ch["P.Z"]) < 1e-4)
        if g.sum() < 100:
            return f"{int(g.sum())} ground pixels"
        p = np.stack([ch["P.X"], ch["P.Y"]], -1)[g].astype(np.float64)
        d = np.array([[0.0, 0.0, 1.0]]) if technique in CENTRAL else _cone(angle)
        t = 1.0 / d[:, 2]  # along each direction to the occluder's plane z = 1
        hx = p[:, None, 0] + t[None] * d[None, :, 0]
        hy = p[:, None, 1] + t[None] * d[None, :, 1]
        exact = 1.0 - ((np.abs(hx) <= OCCLUDER_HALF) & (np.abs(hy) <= OCCLUDER_HALF)).mean(axis=1)
        got = ch["V"][g].astype(np.float64)
        return (None if abs(got.mean() - exact.mean()) <= tol else
                f"mean V {got.mean():.3f} on {int(g.sum())} ground pixels, the cone's exact {exact.mean():.3f}")

    check.__doc__ = f"The mean V over the ground within {tol:g} of the exact visible fraction of a {angle:g}-degree cone."
    return check


for _angle in (60.0, 120.0, 170.0):
    CASES.append(Case(f"wide_sun_{_angle:g}", _wide_sun(_angle), message=("DistantLight angle",), check=cone_visible(_angle),
                      warn_instead=True, silent_hazard=True,
                      note=f"DistantLight angle {_angle:g} overhead: a technique that sizes the sun by tan(angle / 2) warns past "
                           "its distant_angle_limit"))


# -- a rect light whose receivers lie beyond one frustum ---------------------------------------------------

GRAZING_LIGHT = (3.0, 0.0, 0.6)  # a 0.5 x 0.5 rect light facing down, low over a wide ground
GRAZING_OCCLUDER = (0.5, 0.3)  # half-side, height of the occluder square about the z axis


def b_rect_grazing(folder: str) -> str:
    """A 0.5 x 0.5 rect light 0.6 above a ground +-6, a 1 x 1 occluder at z = 0.3: most of the
    ground lies more than 80 degrees off the light's axis, in front of it, much of it in the
    occluder's penumbra."""
    from wsoft.stages.builders import add_camera, add_quad, add_rect_light, make_stage

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    add_quad(st, "/World/Occluder", (0, 0, GRAZING_OCCLUDER[1]), GRAZING_OCCLUDER[0])
    add_rect_light(st, "/World/Light", GRAZING_LIGHT, 0.5, 0.5)
    add_camera(st, "/World/Cam", (0, -9, 7), (-1, 0, 0))
    return _save(st, folder, "rect_grazing")


def grazing_visible(tol: float = 0.02):
    """A check of :func:`b_rect_grazing`'s stage: over the ground more than 80 degrees off the
    light's axis, the mean |V - exact| at most ``tol``; exact: the fraction of the light's area
    (a 16 x 16 grid over it; its centre alone for the fixed-filter techniques of
    :data:`~wsoft.stages.adversarial.checks.CENTRAL`) whose segment to the point misses the occluder."""

    def check(ch, base=None, technique="") -> str | None:
        c = np.asarray(GRAZING_LIGHT)
        g = (ch["A"] > 0) & (np.abs(ch["P.Z"]) < 1e-4)
        dx, dy = ch["P.X"] - c[0], ch["P.Y"] - c[1]
        far = g & (np.degrees(np.arctan2(np.maximum(np.abs(dx), np.abs(dy)), c[2])) > 80.0)
        if far.sum() < 50:
            return f"{int(far.sum())} ground pixels beyond 80 degrees"
        p = np.stack([ch["P.X"], ch["P.Y"]], -1)[far].astype(np.float64)
        u = (np.arange(16) + 0.5) / 16 * 0.5 - 0.25
        pts = np.array([[0.0, 0.0]]) if technique in CENTRAL else np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
        s = GRAZING_OCCLUDER[1] / c[2]  # the segment's parameter at the occluder's plane, from the ground point
        hx = p[:, None, 0] + s * (c[0] + pts[None, :, 0] - p[:, None, 0])
        hy = p[:, None, 1] + s * (c[1] + pts[None, :, 1] - p[:, None, 1])
        h = GRAZING_OCCLUDER[0]
        exact = 1.0 - ((np.abs(hx) <= h) & (np.abs(hy) <= h)).mean(axis=1)
        err = np.abs(ch["V"][far].astype(np.float64) - exact).mean()
        return None if err <= tol else f"mean |V - exact| {err:.3f} on {int(far.sum())} ground pixels beyond 80 degrees off the light's axis"

    check.__doc__ = f"Beyond 80 degrees off the rect light's axis, mean |V - exact| at most {tol:g}."
    return check


CASES.append(Case("rect_grazing", b_rect_grazing, message=("rect light's map in one frustum",), check=grazing_visible(),
                  warn_instead=True, note="rect light low over a wide ground: receivers beyond one frustum's 80 degrees, "
                                          "in front of the light; a technique that leaves them unshadowed says so and what to use"))


# -- emission --------------------------------------------------------------------------------------------


def _emitting(name: str, **inputs):
    def build(folder: str) -> str:
        st = _base()
        light = st.GetPrimAtPath("/World/Light")
        from pxr import Sdf

        for attr, (tname, value) in inputs.items():
            light.CreateAttribute(f"inputs:{attr}", getattr(Sdf.ValueTypeNames, tname)).Set(value)
        return _save(st, folder, name)

    build.__doc__ = f"The base, its light's {', '.join(f'inputs:{k} = {v[1]}' for k, v in inputs.items())}."
    return build


def green_over_red(ch, base=None, technique="") -> str | None:
    """Lit ground shows the light's green and no red or blue beyond the ambient (the base's light
    read as colour (0, 0.5, 0))."""
    lit = (ch["A"] > 0) & (ch["V"] > 0.99)
    if lit.sum() < 100:
        return f"{int(lit.sum())} lit pixels"
    r, gr, b = (float(ch[c][lit].mean()) for c in "RGB")
    return None if gr > 2.0 * max(r, b) else f"mean R G B {r:.3f} {gr:.3f} {b:.3f} on lit pixels: want green well above red and blue"


CASES.append(Case("light_intensity_zero", _emitting("light_intensity_zero", intensity=("Float", 0.0)), "error",
                  ("/World/Light", "emits nothing"), silent_hazard=True,
                  note="the only light has intensity 0: nothing to shadow (it drew the same image as intensity 10)"))
CASES.append(Case("light_intensity_negative", _emitting("light_intensity_negative", intensity=("Float", -5.0)), "error",
                  ("/World/Light", "emits nothing"), silent_hazard=True,
                  note="the only light has intensity -5: warned, read as 0, nothing to shadow"))
CASES.append(Case("light_color_negative", _emitting("light_color_negative", color=("Color3f", (-1.0, 0.5, -2.0))),
                  message=("inputs:color",), check=green_over_red, silent_hazard=True,
                  note="light colour (-1, 0.5, -2): warned, read as (0, 0.5, 0); the image is green"))


# -- render settings that leave nothing to draw -------------------------------------------------------------


def b_purposes_empty(folder: str) -> str:
    """The base with the stage's render settings (``renderSettingsPrimPath``) including no purpose:
    ``includedPurposes = []``."""
    from pxr import UsdRender

    st = _base()
    rs = UsdRender.Settings.Define(st, "/Render/Settings")
    rs.CreateIncludedPurposesAttr([])
    rs.CreateCameraRel().SetTargets(["/World/Cam"])
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    return _save(st, folder, "purposes_empty")


CASES.append(Case("purposes_empty", b_purposes_empty, "error", ("/Render/Settings", "includedPurposes", "nothing to draw"),
                  silent_hazard=True, note="render settings with includedPurposes = []: their purposes leave nothing to draw "
                                           "(it answered 'no shadow-casting light')"))
