"""A ``UsdLux.DomeLight`` (or ``DomeLight_1``) -> a :class:`~wsoft.scene.types.Light` of kind ``dome`` (:mod:`wsoft.scene.dome`).

:func:`read_dome` reads the emission as for every light (``inputs:color``, ``inputs:intensity x
2^inputs:exposure``, the blackbody colour; ``inputs:normalize`` does not apply to a dome: UsdLux
normalises by the light's size and a dome has none), the dome's orientation (the prim's world
rotation, its scale and translation dropped; ``DomeLight_1``'s ``poleAxis``: the pole turned onto
+Z by a +90 degree turn about X where it is ``Z``, or ``scene`` on a Z-up stage) and
``inputs:texture:file`` with ``inputs:texture:format`` ``automatic`` or ``latlong`` (the others
refused in one line): an OpenEXR file (its R, G, B), a Radiance ``.hdr`` (:mod:`wsoft.rgbe`),
or an 8- or 16-bit image Pillow reads (sRGB-encoded 8-bit colour decoded to linear). A texture that
cannot be read is an error naming the file, the prim and the attribute (exit 2). A dome with
``portals`` gets a warning: portals are not honoured.
"""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.scene.dome import LIGHT_DOME, Dome
from wsoft.scene.types import Light
from wsoft.scene.usd_context import StageContext, pxr

TEXTURE_FORMATS = ("automatic", "latlong")  # inputs:texture:format values read
MAX_DOME_PIXELS = 4096 * 2048  # a larger dome texture is refused (its sampling table alone would be hundreds of MB)
POLE_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # +90 degrees about X: the dome's +Y pole onto +Z


def read_dome(ctx: StageContext, prim, type_name: str, base: Light) -> Light:
    """The dome light ``prim`` (``type_name`` ``DomeLight`` or ``DomeLight_1``); ``base``: the
    light as :func:`~wsoft.scene.usd_lights.read_light_shape` reads every light's emission (its
    ``color``, ``intensity`` and frame)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    rotation = np.asarray(base.frame, np.float64)
    if np.linalg.det(rotation) < 0.0:  # a mirrored dome: the sky seen in a mirror, kept as authored
        ctx.warn(prim, "the dome's transform mirrors it (negative determinant): its texture is drawn mirrored, as the transform says")
    if type_name == "DomeLight_1":
        pole = str(ctx.get(UsdLux.DomeLight_1(prim).GetPoleAxisAttr(), "scene"))
        if pole == "Z" or (pole == "scene" and UsdGeom.GetStageUpAxis(ctx.stage) == UsdGeom.Tokens.z):
            rotation = rotation @ POLE_Z
    lux = UsdLux.DomeLight(prim) if type_name == "DomeLight" else UsdLux.DomeLight_1(prim)
    fmt = str(ctx.get(lux.GetTextureFormatAttr(), "automatic"))
    asset = ctx.get(lux.GetTextureFileAttr(), None)
    texture, label = None, ""
    if asset is not None and getattr(asset, "path", ""):
        if fmt not in TEXTURE_FORMATS:
            raise ctx.err(prim, f"inputs:texture:format = {fmt}: only {' and '.join(TEXTURE_FORMATS)} (a latlong image) are read; "
                          "convert the texture to a latlong (equirectangular) image")
        resolved = asset.resolvedPath or ""
        label = resolved or asset.path
        texture = read_latlong(ctx, prim, asset.path, resolved)
    portals = lux.GetPortalsRel().GetTargets() if lux.GetPortalsRel() else []
    if portals:
        ctx.warn(prim, f"portals ({', '.join(str(p) for p in portals)}) are not honoured: the dome lights every receiver from its "
                 "whole sky (remove the portals, or model the openings' occluders)")
    if bool(ctx.get(lux.GetNormalizeAttr(), False)):
        ctx.warn(prim, "inputs:normalize has no effect on a DomeLight (it divides by the light's size, and a dome has none)")
    dome = Dome(texture=texture, rotation=rotation, asset=label)
    return Light(path=base.path, kind=LIGHT_DOME, position=np.zeros(3), frame=rotation, intensity=base.intensity, color=base.color,
                 dome=dome)


def read_latlong(ctx: StageContext, prim, authored: str, resolved: str) -> np.ndarray:
    """The latlong texture ``authored`` (``resolved`` by USD's asset resolver) as linear RGB,
    ``[H, W, 3]`` float32, row 0 the zenith; unreadable, or not 2:1, an error naming file, prim and
    attribute."""
    from wsoft.rgbe import RgbeError, read_rgbe
    from wsoft.scene.usd_texture import TextureError, _read_asset, decode, srgb_to_linear

    where = f"inputs:texture:file = {authored}"
    data = _read_asset(resolved) if resolved else None
    if data is None:
        raise ctx.err(prim, f"{where}: the file cannot be found or opened")
    try:
        if data.startswith((b"#?RADIANCE", b"#?RGBE")):
            rgb = read_rgbe(data)
        else:
            planes = [decode(data, c, resolved if os.path.isfile(resolved) else None) for c in "rgb"]
            rgb = np.stack([p.values for p in planes], axis=-1).astype(np.float32)
            if planes[0].srgb_auto:
                rgb = srgb_to_linear(rgb)
    except (RgbeError, TextureError) as exc:
        raise ctx.err(prim, f"{where}: the image {exc}") from None
    h, w = rgb.shape[:2]
    if h * w > MAX_DOME_PIXELS:
        raise ctx.err(prim, f"{where}: the image is {w} x {h}, over wsoft's dome limit of {MAX_DOME_PIXELS} pixels "
                      "(wsoft.scene.usd_dome.MAX_DOME_PIXELS); downsample it")
    if w != 2 * h:
        raise ctx.err(prim, f"{where}: the image is {w} x {h}, not a latlong image (width = 2 x height)")
    bad = ~np.isfinite(rgb)
    if bad.any():
        raise ctx.err(prim, f"{where}: the image has {int(bad.any(axis=2).sum())} pixels that are NaN or infinite")
    if rgb.min() < 0.0:
        ctx.warn(prim, f"{where}: the image has negative radiance (min {float(rgb.min()):g}): read as 0 (no sky emits less than "
                 "nothing)")
        rgb = np.maximum(rgb, 0.0)
    if not rgb.max() > 0.0:
        ctx.warn(prim, f"{where}: the image is black: the dome emits nothing (V = 1 everywhere, no light added); author a sky with "
                 "radiance, or remove the light")
    return np.ascontiguousarray(rgb, np.float32)


def dome_brightest_direction(light) -> np.ndarray:
    """The world direction of the dome texture's brightest texel (luminance), unit; the pole for a constant dome."""
    from wsoft.scene.dome import LUMINANCE, texel_directions

    dome: Dome = light.dome
    if dome.texture is None:
        return dome.rotation[:, 1].copy()
    lum = np.asarray(dome.texture, np.float64) @ np.asarray(LUMINANCE)
    i, j = np.unravel_index(int(np.argmax(lum)), lum.shape)
    d = texel_directions(lum.shape)[i, j]
    d = dome.rotation @ d
    return d / math.sqrt(float(d @ d))
