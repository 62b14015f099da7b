"""Small stages with known answers for lights as production stages author them (``wsoft bench lights``,
``tests/test_dome.py``): a uniform or polar-cap dome over a parallel square, and a spot over a ground.

Closed forms beside them: :func:`form_factor` (a point to a parallel rectangle, the uniform dome's
``V = 1 - F``) and :func:`cap_visibility` (the polar-cap dome, by a fine quadrature).
"""

from __future__ import annotations

import math

import numpy as np
from pxr import Sdf, UsdGeom, UsdLux

from wsoft.stages.builders import add_box, add_camera, add_point_light, add_quad, add_sphere_light, make_stage

SQUARE = (-0.5, 0.5, -0.5, 0.5)  # the occluder square's x and y extents, at height 1
SPOT_HEIGHT = 3.0  # the spot's height over the ground


def corner_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to the rectangle [0, a] x [0, b] parallel to its plane at height
    ``h`` with a corner straight above it (signed by the signs of ``a`` and ``b``)."""
    A, B = abs(a) / h, abs(b) / h
    sa, sb = math.sqrt(1 + A * A), math.sqrt(1 + B * B)
    return math.copysign(1, a) * math.copysign(1, b) * (A / sa * math.atan(B / sa) + B / sb * math.atan(A / sb)) / (2 * math.pi)


def form_factor(px: float, py: float, rect=SQUARE, h: float = 1.0) -> float:
    """From the point (px, py, 0) facing +Z to the parallel rectangle ``rect`` = (x0, x1, y0, y1) at
    height ``h``: four corner rectangles superposed with signs."""
    x0, x1, y0, y1 = rect
    return (corner_factor(x1 - px, y1 - py, h) - corner_factor(x0 - px, y1 - py, h) - corner_factor(x1 - px, y0 - py, h)
            + corner_factor(x0 - px, y0 - py, h))


def cap_visibility(px: float, py: float, cap_deg: float = 30.0, rect=SQUARE, h: float = 1.0, steps: int = 300) -> float:
    """V at (px, py, 0) facing +Z under a dome of radiance 1 within ``cap_deg`` of the zenith (0
    elsewhere) over the rectangle ``rect`` at height ``h``: 1 - the cosine-weighted share of the cap
    the rectangle hides, by the midpoint rule on ``steps`` x ``2 steps`` cells of the cap."""
    th = np.radians((np.arange(steps) + 0.5) * cap_deg / steps)
    ph = np.radians((np.arange(2 * steps) + 0.5) * 180.0 / steps)
    T, P = np.meshgrid(th, ph, indexing="ij")
    w = np.cos(T) * np.sin(T)
    x, y = px + h * np.tan(T) * np.cos(P), py + h * np.tan(T) * np.sin(P)
    hit = (x >= rect[0]) & (x <= rect[1]) & (y >= rect[2]) & (y <= rect[3])
    return 1.0 - float((w * hit).sum() / w.sum())


def cap_texture(h: int = 24, cap_deg: float = 60.0) -> np.ndarray:
    """A latlong radiance image ``[h, 2h, 3]``: 1 at latitudes above ``cap_deg`` (whole rows), 0 below."""
    t = np.zeros((h, 2 * h, 3), np.float32)
    t[: int(round(h * (90.0 - cap_deg) / 180.0))] = 1.0
    return t


def dome_square_stage(texture: str | None = None, *, fmt: str | None = None, occluder: bool = True, path: str | None = None, **inputs):
    """A ground +-6 and the square occluder :data:`SQUARE` at height 1 under a DomeLight ``/World/Sky``
    turned +90 degrees about X (its +Y pole on the stage's +Z), the camera looking in under the
    square; ``texture``: its ``inputs:texture:file`` (``fmt``: ``inputs:texture:format``); ``inputs``:
    DomeLight inputs by schema name (``Intensity=2.0``)."""
    st = make_stage("Z", path)
    add_quad(st, "/World/Ground", (0, 0, 0), 6.0)
    if occluder:
        add_quad(st, "/World/Occluder", (0, 0, 1), 0.5)
    add_camera(st, "/World/Camera", (0, -3, 2.0), (0, 0.3, 0))
    dome = UsdLux.DomeLight.Define(st, "/World/Sky")
    UsdGeom.Xformable(dome).AddRotateXOp().Set(90.0)
    if texture is not None:
        dome.CreateTextureFileAttr(Sdf.AssetPath(texture))
    if fmt is not None:
        dome.CreateTextureFormatAttr(fmt)
    for k, v in inputs.items():
        getattr(dome, f"Create{k}Attr")(v)
    return st


def spot_stage(cone: float | None = 30.0, *, radius: float = 0.1, box: bool = True, point: bool = False, path: str | None = None):
    """A ground +-5, optionally a 0.6 box under the light, and a light :data:`SPOT_HEIGHT` over the
    origin facing down (a sphere light of ``radius``, or a point light) with ``UsdLux.ShapingAPI``
    ``cone`` degrees (None: no ShapingAPI); the camera looking down from the side."""
    st = make_stage("Z", path)
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    if box:
        add_box(st, "/World/Box", (-0.3, -0.3, 0), (0.3, 0.3, 0.6))
    light = add_point_light(st, "/World/Light", (0, 0, SPOT_HEIGHT)) if point else add_sphere_light(st, "/World/Light", (0, 0, SPOT_HEIGHT), radius)
    if cone is not None:
        UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingConeAngleAttr(float(cone))
    add_camera(st, "/World/Cam", (0, -7, 6), (0.5, 0, 0))
    return st


def off_axis_deg(frame) -> np.ndarray:
    """Degrees off the spot's axis (straight down from (0, 0, SPOT_HEIGHT)) of each pixel's point."""
    r = np.hypot(frame["P.X"], frame["P.Y"])
    return np.degrees(np.arctan2(r, SPOT_HEIGHT - frame["P.Z"]))
