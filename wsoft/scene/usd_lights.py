"""USD lights with their shadow controls, and cameras -> :class:`~wsoft.scene.types.Light`, :class:`~wsoft.scene.types.Camera`.

:func:`read_light` reads the lights wsoft shadows (:data:`HANDLED_LIGHTS`: rect, disk, sphere,
cylinder, distant and dome (:mod:`wsoft.scene.usd_dome`); the others are skipped with :data:`UNHANDLED_REASONS`) from their ``inputs:`` at the
context's time code, their frame re-orthonormalised and their sizes scaled by the transform, and
their emission as UsdLux defines it (:func:`read_emission`; a light that emits nothing is skipped,
:func:`emission_refusal`);
:func:`read_shadow_controls` adds the ``UsdLux.ShadowAPI`` controls (shadow linking, distance,
colour, falloff). :func:`read_camera` reads a ``UsdGeom.Camera``; :func:`auto_camera` frames a scene
that has none.
"""

from __future__ import annotations

import math

import numpy as np

from wsoft.scene.dome import LIGHT_DOME
from wsoft.scene.ies import IesError, read_ies
from wsoft.scene.shaping import Shaping
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_POINT, LIGHT_RECT, LIGHT_SPHERE, Camera, Light, Scene
from wsoft.scene.usd_context import StageContext, pxr
from wsoft.scene.usd_dome import read_dome

DOME_LIGHTS = ("DomeLight", "DomeLight_1")  # the sky (wsoft.scene.dome, read by wsoft.scene.usd_dome)
HANDLED_LIGHTS = ("RectLight", "DiskLight", "SphereLight", "CylinderLight", "DistantLight", *DOME_LIGHTS)
UNHANDLED_REASONS = {
    "GeometryLight": "mesh (geometry) lights are not handled by any technique",
    "PortalLight": "portal lights (openings a DomeLight's light is restricted to) are not honoured: the dome lights every receiver "
                   "from its whole sky",
    "PluginLight": "plugin lights have no known shape; not handled",
}


ROUND = 1e-6  # scale factors within this fraction of each other are one radius (a rotation's rounding makes no ellipse)


def read_light(ctx: StageContext, prim, type_name: str) -> Light | None:
    """The light ``prim`` in the world (:func:`read_light_shape`), its ``intensity`` and ``color``
    its emission (:func:`read_emission`)."""
    light = read_light_shape(ctx, prim, type_name)
    if light is not None and light.kind == LIGHT_DOME:
        return read_dome(ctx, prim, type_name, read_emission(ctx, prim, light))
    return None if light is None else read_shaping(ctx, prim, read_emission(ctx, prim, light))


SHAPING_ATTRS = ("inputs:shaping:cone:angle", "inputs:shaping:cone:softness", "inputs:shaping:focus", "inputs:shaping:focusTint",
                 "inputs:shaping:ies:file", "inputs:shaping:ies:angleScale", "inputs:shaping:ies:normalize")


def read_shaping(ctx: StageContext, prim, light: Light) -> Light:
    """``light`` with its ``UsdLux.ShapingAPI`` (primary axis local −Z), read where the API is applied
    or any of its inputs authored: ``shaping:cone:angle`` (fallback 90; in [0, 180] degrees),
    ``shaping:cone:softness`` (>= 0; above 1 read as 1), ``shaping:focus`` (>= 0) and
    ``shaping:focusTint``; a value out of range or not finite is an error naming the attribute.
    ``shaping:ies:file`` (an LM-63 profile, :func:`read_ies_shaping`) with ``shaping:ies:angleScale``
    (> -1) and ``shaping:ies:normalize``. A distant light's
    emission has one direction, which a cone about its own axis does not cut: its authored shaping
    gets a warning and is not applied."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    api = UsdLux.ShapingAPI(prim)
    authored = any(prim.HasAttribute(a) and prim.GetAttribute(a).HasAuthoredValue() for a in SHAPING_ATTRS)
    if not (prim.HasAPI(UsdLux.ShapingAPI) or authored):
        return light
    ies = read_ies_shaping(ctx, prim, api)
    angle = ctx.finite(prim, "inputs:shaping:cone:angle", ctx.get(api.GetShapingConeAngleAttr(), 90.0))
    if not 0.0 <= angle <= 180.0:
        raise ctx.err(prim, f"inputs:shaping:cone:angle = {angle:g} must be in [0, 180] degrees off the light's axis")
    soft = ctx.finite(prim, "inputs:shaping:cone:softness", ctx.get(api.GetShapingConeSoftnessAttr(), 0.0))
    if soft < 0.0:
        raise ctx.err(prim, f"inputs:shaping:cone:softness = {soft:g} is negative (0 is a hard edge, 1 the softest)")
    focus = ctx.finite(prim, "inputs:shaping:focus", ctx.get(api.GetShapingFocusAttr(), 0.0))
    if focus < 0.0:
        raise ctx.err(prim, f"inputs:shaping:focus = {focus:g} is negative (0 is no focus)")
    tint = tuple(float(c) for c in ctx.get(api.GetShapingFocusTintAttr(), (0.0, 0.0, 0.0)))
    if not all(math.isfinite(c) for c in tint):
        raise ctx.err(prim, f"inputs:shaping:focusTint = {tint} is not finite")
    if min(tint) < 0.0:
        raise ctx.err(prim, f"inputs:shaping:focusTint = ({', '.join(f'{c:g}' for c in tint)}) has negative components")
    if light.kind == LIGHT_DISTANT:
        if authored:
            ctx.warn(prim, "ShapingAPI on a DistantLight is not applied (its light arrives along one direction, which no cone "
                     "about its axis cuts): remove the shaping inputs, or use a rect, disk or sphere light for a spot")
        return light
    light.shaping = Shaping(cone_deg=angle, softness=min(soft, 1.0), focus=focus, focus_tint=tint, **ies)
    return light


def read_ies_shaping(ctx: StageContext, prim, api) -> dict:
    """The ``Shaping`` fields of ``shaping:ies:file`` (resolved by the stage's asset resolver, else
    taken as written; the profile read by :func:`~wsoft.scene.ies.read_ies`),
    ``shaping:ies:angleScale`` (finite, > -1: ``1 + angleScale`` divides the profile's angles,
    :func:`~wsoft.scene.ies.ies_angle`) and ``shaping:ies:normalize``; none without a file. A file
    that is missing or malformed, or an angle scale out of range, is an error naming the attribute."""
    asset = ctx.get(api.GetShapingIesFileAttr(), None)
    written = getattr(asset, "path", str(asset or ""))
    if not written:
        return {}
    path = getattr(asset, "resolvedPath", "") or written
    try:
        profile = read_ies(path)
    except IesError as e:
        raise ctx.err(prim, f"inputs:shaping:ies:file = {written}: {e}") from None
    scale = ctx.finite(prim, "inputs:shaping:ies:angleScale", ctx.get(api.GetShapingIesAngleScaleAttr(), 0.0))
    if scale <= -1.0:
        raise ctx.err(prim, f"inputs:shaping:ies:angleScale = {scale:g} must be > -1 (the profile's angles are divided by "
                      "1 + angleScale; 0 leaves them as they are)")
    normalize = bool(ctx.get(api.GetShapingIesNormalizeAttr(), False))
    return dict(ies=profile, ies_path=path, ies_angle_scale=scale, ies_normalize=normalize)


EMITS_NOTHING = "emits nothing"
"""The start of the reason a light that emits no light is skipped for (:func:`emission_refusal`)."""


def read_emission(ctx: StageContext, prim, light: Light) -> Light:
    """``light`` with its UsdLux emission: ``intensity`` = ``inputs:intensity x 2^inputs:exposure``,
    divided by its size where ``inputs:normalize`` is on (:func:`size_factor`); ``color`` =
    ``inputs:color``, times ``UsdLux.BlackbodyTemperatureAsRgb(inputs:colorTemperature)`` where
    ``inputs:enableColorTemperature`` is on. A negative intensity (the light then emits nothing,
    :func:`emission_refusal`) or colour component (read as 0) gets a warning: no light emits less
    than nothing."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    lux = UsdLux.LightAPI(prim)
    if light.intensity < 0.0:  # kept as authored: emission_refusal skips the light, naming it
        ctx.warn(prim, f"inputs:intensity x 2^inputs:exposure = {light.intensity:g} is negative (no light emits less than nothing): "
                 "this light emits nothing and is skipped; author an intensity >= 0")
    if min(light.color) < 0.0:
        fixed = tuple(max(c, 0.0) for c in light.color)
        ctx.warn(prim, f"inputs:color = ({', '.join(f'{c:g}' for c in light.color)}) has negative components (no light emits less "
                 f"than nothing): read as ({', '.join(f'{c:g}' for c in fixed)}); author components >= 0")
        light.color = fixed
    if bool(ctx.get(lux.GetEnableColorTemperatureAttr(), False)):
        t = ctx.finite(prim, "inputs:colorTemperature", ctx.get(lux.GetColorTemperatureAttr(), 6500.0))
        if t <= 0.0:
            raise ctx.err(prim, f"inputs:colorTemperature = {t:g} must be > 0 (kelvin)")
        bb = UsdLux.BlackbodyTemperatureAsRgb(t)
        light.color = tuple(float(c) * float(b) for c, b in zip(light.color, bb))
    if bool(ctx.get(lux.GetNormalizeAttr(), False)):
        f = size_factor(light)
        if f > 0.0:
            light.intensity /= f
    return light


def size_factor(light: Light) -> float:
    """UsdLux's ``sizeFactor`` of ``inputs:normalize``: an area light's world-space surface area (a
    rect's, a disk's, a sphere's or ellipsoid's (Knud Thomsen's approximation), a cylinder's side),
    a distant light's ``pi sin^2(theta)`` (``(2 - sin^2(theta)) pi`` past 90 degrees, theta its half
    angle; 1 at angle 0); 1 for a point light or a shape of no area."""
    a = light.aspect
    r = light.radius
    if light.kind == LIGHT_RECT:
        return 4.0 * light.half_size[0] * light.half_size[1] or 1.0
    if light.kind == LIGHT_DISK:
        return math.pi * r * r * a[0] * a[1] or 1.0
    if light.kind == LIGHT_SPHERE:
        x, y, z = (r * c for c in a)
        p = 1.6075
        return 4.0 * math.pi * (((x * y) ** p + (x * z) ** p + (y * z) ** p) / 3.0) ** (1.0 / p) or 1.0
    if light.kind == LIGHT_CYLINDER:
        return 2.0 * math.pi * light.half_size[1] * 2.0 * light.half_size[0] or 1.0
    if light.kind == LIGHT_DISTANT:
        t = math.radians(0.5 * light.angle_deg)
        if t <= 0.0:
            return 1.0
        return math.pi * math.sin(t) ** 2 if t <= 0.5 * math.pi else (2.0 - math.sin(t) ** 2) * math.pi
    return 1.0


def emission_refusal(light: Light) -> str | None:
    """Why ``light`` is skipped for emitting nothing (its intensity, or every colour channel, 0), else None."""
    if light.intensity > 0.0 and max(light.color) > 0.0:
        return None
    return (f"{EMITS_NOTHING} (intensity x 2^exposure {light.intensity:g}, color ({', '.join(f'{c:g}' for c in light.color)})): "
            "no light, so no shadow to draw")


def read_light_shape(ctx: StageContext, prim, type_name: str) -> Light | None:
    """The light ``prim`` (``type_name`` one of :data:`HANDLED_LIGHTS`) in the world: a rect light
    spans +-width/2, +-height/2 in its local XY plane, a disk light its radius there, a sphere light
    its radius about its origin (a sphere treated as a point, or of radius 0, is a point light), a
    cylinder light the side of a cylinder of ``length`` along its local X and ``radius`` about its
    origin (end caps do not emit), a distant light its full ``angle`` in degrees; sizes scaled by
    the transform, intensity by ``2^exposure``.

    A cylinder's length is scaled by the transform's X scale and its radius by the mean of its Y
    and Z scales (unequal ones, an elliptical cross-section, are rendered round, with a warning).
    ``treatAsLine`` (UsdLux: "effectively, a zero-radius cylinder") or radius 0 makes it a line
    light of that length (:attr:`~wsoft.scene.types.Light.is_line`); length 0 leaves a side of no
    area, rendered as a point light at its origin with a warning. ``inputs:intensity`` and
    ``inputs:normalize`` scale how much light it emits, not which part of it a point sees: ``V``
    does not depend on them.

    The frame's columns are the transformed local axes, normalised (and re-orthonormalised under
    shear). A mirroring transform (a negative determinant) keeps its reflection: the light's Z axis
    is where the transform takes the local Z axis, so a rect or disk light emits along the
    transformed local −Z whatever the handedness (scale (1, 1, −1) turns it round, (−1, 1, 1)
    leaves it facing the same way). Under a non-uniform scale a disk is the ellipse of semi-axes
    ``radius * scale`` along its X and Y and a sphere the ellipsoid the transform makes of it
    (semi-axes ``radius`` times the transform's singular values, along their directions)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    M = ctx.world(prim)
    axes = M[:3, :3]
    scale = np.linalg.norm(axes, axis=0)
    if np.any(scale < 1e-12) or not np.all(np.isfinite(M)):
        raise ctx.err(prim, "light transform is singular or not finite")
    frame = axes / scale
    # re-orthonormalise (shear would make the frame skew); the nearest orthogonal matrix keeps a reflection
    u, _, vt = np.linalg.svd(frame)
    frame = u @ vt
    pos = M[:3, 3].copy()
    lux = UsdLux.LightAPI(prim)
    intensity = ctx.finite(prim, "inputs:intensity", ctx.get(lux.GetIntensityAttr(), 1.0))
    exposure = ctx.finite(prim, "inputs:exposure", ctx.get(lux.GetExposureAttr(), 0.0))
    if not -126.0 <= exposure <= 127.0:
        raise ctx.err(prim, f"inputs:exposure = {exposure:g} is out of range (2^exposure must be a finite float: -126..127)")
    intensity *= 2.0 ** exposure
    color = tuple(float(c) for c in ctx.get(lux.GetColorAttr(), (1.0, 1.0, 1.0)))
    if not all(math.isfinite(c) for c in color):
        raise ctx.err(prim, f"inputs:color = {color} is not finite")
    common = dict(path=str(prim.GetPath()), position=pos, frame=frame, intensity=intensity, color=color)
    if type_name in DOME_LIGHTS:
        return Light(kind=LIGHT_DOME, **common)
    if type_name == "RectLight":
        lt = UsdLux.RectLight(prim)
        w = ctx.size(prim, "inputs:width", ctx.get(lt.GetWidthAttr(), 1.0)) * scale[0]
        h = ctx.size(prim, "inputs:height", ctx.get(lt.GetHeightAttr(), 1.0)) * scale[1]
        if w == 0 and h == 0:
            ctx.warn(prim, "RectLight has zero width and height: rendered as a point light (hard shadows)")
            return Light(kind=LIGHT_POINT, **common)
        if w == 0 or h == 0:
            ctx.warn(prim, f"RectLight has zero {'width' if w == 0 else 'height'}: it emits from a line segment (no area)")
        return Light(kind=LIGHT_RECT, half_size=(0.5 * w, 0.5 * h), **common)
    if type_name == "DiskLight":
        r0 = ctx.size(prim, "inputs:radius", ctx.get(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5))
        r = r0 * 0.5 * (scale[0] + scale[1])
        if r == 0:
            ctx.warn(prim, "DiskLight has radius 0: rendered as a point light (hard shadows)")
            return Light(kind=LIGHT_POINT, **common)
        if _round(scale[:2]):
            return Light(kind=LIGHT_DISK, radius=r, **common)
        semi = r0 * scale[:2]
        return Light(kind=LIGHT_DISK, radius=float(semi.max()), aspect=(*(float(a) for a in semi / semi.max()), 1.0), **common)
    if type_name == "SphereLight":
        lt = UsdLux.SphereLight(prim)
        r0 = ctx.size(prim, "inputs:radius", ctx.get(lt.GetRadiusAttr(), 0.5))
        r = r0 * float(np.mean(scale))
        if bool(ctx.get(lt.GetTreatAsPointAttr(), False)) or r <= 0:
            return Light(kind=LIGHT_POINT, **common)
        sv_u, sv, _ = np.linalg.svd(axes)  # the unit ball's image: semi-axes r0 * sv along sv_u's columns
        if _round(sv):
            return Light(kind=LIGHT_SPHERE, radius=r, **common)
        if np.linalg.det(sv_u) < 0:
            sv_u[:, 2] = -sv_u[:, 2]  # a ball has no handedness: its frame a rotation
        common["frame"] = sv_u
        return Light(kind=LIGHT_SPHERE, radius=float(r0 * sv[0]), aspect=tuple(float(a) for a in sv / sv[0]), **common)
    if type_name == "CylinderLight":
        lt = UsdLux.CylinderLight(prim)
        length = ctx.size(prim, "inputs:length", ctx.get(lt.GetLengthAttr(), 1.0)) * float(scale[0])
        r0 = ctx.size(prim, "inputs:radius", ctx.get(lt.GetRadiusAttr(), 0.5))
        line = bool(ctx.get(lt.GetTreatAsLineAttr(), False))
        r = 0.0 if line else r0 * 0.5 * float(scale[1] + scale[2])
        if length == 0:
            ctx.warn(prim, "CylinderLight has length 0: its side has no area; rendered as a point light (hard shadows)")
            return Light(kind=LIGHT_POINT, **common)
        if r0 == 0 and not line:
            ctx.warn(prim, "CylinderLight has radius 0: rendered as a line light")
        if r > 0 and not _round(scale[1:]):
            ctx.warn(prim, f"CylinderLight scaled unequally across its axis (Y {scale[1]:g}, Z {scale[2]:g}): its elliptical "
                     f"cross-section is rendered round, of the mean radius {r:g}")
        return Light(kind=LIGHT_CYLINDER, half_size=(0.5 * length, r), radius=r, **common)
    angle = ctx.finite(prim, "inputs:angle", ctx.get(UsdLux.DistantLight(prim).GetAngleAttr(), 0.53))
    if not (0.0 <= angle < 180.0):
        raise ctx.err(prim, f"DistantLight angle {angle} must be in [0, 180) degrees")
    return Light(kind=LIGHT_DISTANT, angle_deg=angle, **common)


def _round(s: np.ndarray) -> bool:
    """Are the scale factors ``s`` equal, to within a fraction :data:`ROUND` of the largest?"""
    return float(s.max() - s.min()) <= ROUND * float(s.max())


def read_shadow_controls(ctx: StageContext, prim, light: Light, casters: list[str]) -> Light:
    """The UsdLux controls that change who casts ``light``'s shadow and how it is shaded, onto
    the light: ``collection:shadowLink`` (membership as ``Usd.CollectionAPI`` computes it;
    unauthored, USD's ``includeRoot = true`` includes everything) as the prims it leaves out,
    ``inputs:shadow:distance``, ``inputs:shadow:color``, ``inputs:shadow:falloff`` and
    ``falloffGamma``. A mesh placed by a PointInstancer casts when both the instancer and the
    prototype mesh are members. Falloff is read but not applied: a warning when authored."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    link = UsdLux.LightAPI(prim).GetShadowLinkCollectionAPI()
    excluded = []
    if link:
        query = link.ComputeMembershipQuery()
        for i, c in enumerate(casters):
            paths = {c.split("@")[0], c.split("@")[-1].split("[")[0]}  # the mesh, and its instancer if any
            if not all(query.IsPathIncluded(Sdf.Path(q)) for q in paths):
                excluded.append(i)
    shadow = UsdLux.ShadowAPI(prim)
    dist = ctx.get(shadow.GetShadowDistanceAttr(), -1.0)
    dist = float(dist)
    if math.isnan(dist):
        raise ctx.err(prim, "inputs:shadow:distance = nan is not a number")
    if dist < 0.0 or math.isinf(dist):
        dist = -1.0  # USD: -1 (any negative value, or an infinite one) is no limit
    color = tuple(float(c) for c in ctx.get(shadow.GetShadowColorAttr(), (0.0, 0.0, 0.0)))
    if not all(math.isfinite(c) for c in color):
        raise ctx.err(prim, f"inputs:shadow:color = {color} is not finite")
    falloff = ctx.finite(prim, "inputs:shadow:falloff", ctx.get(shadow.GetShadowFalloffAttr(), -1.0))
    gamma = ctx.finite(prim, "inputs:shadow:falloffGamma", ctx.get(shadow.GetShadowFalloffGammaAttr(), 1.0))
    if falloff > 0.0:
        ctx.warn(prim, f"inputs:shadow:falloff = {falloff:g} (falloffGamma {gamma:g}) is not applied: the shadow ends "
                 "sharply at inputs:shadow:distance (UsdLux gives no formula for the fade)")
    light.shadow_excluded = tuple(excluded)
    light.shadow_distance = dist
    light.shadow_color = color
    light.shadow_falloff = falloff
    light.shadow_falloff_gamma = gamma
    return light


def read_camera(ctx: StageContext, prim) -> Camera:
    """The ``UsdGeom.Camera`` ``prim`` at the context's time code: its frame (scale removed),
    projection, apertures as tangents of the half angles (orthographic: half extents) and their
    offsets, and clipping range."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    cam = UsdGeom.Camera(prim).GetCamera(ctx.timecode)
    M = np.array(cam.transform, dtype=np.float64).T
    axes = M[:3, :3]
    scale = np.linalg.norm(axes, axis=0)
    if np.any(scale < 1e-12) or not np.all(np.isfinite(M)):
        raise ctx.err(prim, "camera transform is singular or not finite")
    M[:3, :3] = axes / scale
    clip = (float(cam.clippingRange.min), float(cam.clippingRange.max))
    if not all(math.isfinite(c) for c in clip) or not 0.0 <= clip[0] < clip[1]:
        ctx.warn(prim, f"clippingRange {clip} is empty or inverted (need 0 <= near < far): this camera sees nothing")
    ortho = cam.projection == Gf.Camera.Orthographic
    ha, va = float(cam.horizontalAperture), float(cam.verticalAperture)
    ho, vo = float(cam.horizontalApertureOffset), float(cam.verticalApertureOffset)
    if ha <= 0 or va <= 0:
        raise ctx.err(prim, "camera apertures must be > 0")
    if ortho:
        # apertures are in tenths of a scene unit
        tan_half = (0.05 * ha, 0.05 * va)
        offset = (0.1 * ho, 0.1 * vo)
    else:
        f = float(cam.focalLength)
        if f <= 0:
            raise ctx.err(prim, "camera focalLength must be > 0")
        tan_half = (0.5 * ha / f, 0.5 * va / f)
        offset = (ho / f, vo / f)
    return Camera(path=str(prim.GetPath()), to_world=M, orthographic=ortho, tan_half=tan_half, offset=offset, clip=clip)


def auto_camera(scene: Scene, aspect: float = 4.0 / 3.0) -> Camera:
    """A perspective camera looking down at the scene from above and to the side (up-axis aware),
    placed at the smallest distance at which all 8 corners of the scene's bounds are in view."""
    lo, hi = scene.bounds
    center = 0.5 * (lo + hi)
    up = np.array([0.0, 0.0, 1.0]) if scene.up_axis == "Z" else np.array([0.0, 1.0, 0.0])
    side = np.array([1.0, 0.0, 0.0])
    fwd_h = np.cross(up, side)  # a horizontal direction
    view_dir = -(0.55 * up + 0.6 * fwd_h + 0.35 * side)
    view_dir /= np.linalg.norm(view_dir)
    z = -view_dir
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    tan_x = math.tan(math.radians(27.0))
    tan_y = tan_x / aspect
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]) - center
    cx, cy, cz = corners @ x, corners @ y, corners @ z
    dist = float(np.max(np.maximum(cz + np.abs(cx) / tan_x, cz + np.abs(cy) / tan_y))) * 1.02
    dist = max(dist, 1e-3 * scene.diagonal)
    eye = center + z * dist
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, z, eye
    return Camera(path="(automatic)", to_world=M, tan_half=(tan_x, tan_y), clip=(dist * 1e-4, dist + 2 * scene.diagonal))
