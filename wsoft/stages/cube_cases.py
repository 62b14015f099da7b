"""Stages that measure cube maps (``wsoft bench cube``, ``tests/test_cube_maps.py``): a ring of posts
around a sphere light whose shadows cross the cube's face edges, and a field of posts under a
sphere light seen out to a chosen angle off the light's axis (where one frustum stops sufficing)."""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.stages.builders import add_box, add_camera, add_quad, make_stage


def ring_stage(folder: str, rotate_deg: float = 0.0, name: str | None = None) -> str:
    """A sphere light (radius 0.25) 1 above a wide floor and a ring of 16 posts 1.3 from below it,
    whose shadows cross the cube's face edges on the floor (the square |x| = 1 and the diagonals
    |x| = |y| of the faces' tangents); the light's frame turned by ``rotate_deg`` about the
    vertical moves the edges, not the shadows. A camera looks down at the ring."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Floor", (0, 0, 0), 6)
    for n, ang in enumerate(np.arange(0, 360, 22.5)):
        a = math.radians(float(ang))
        c = (1.3 * math.cos(a), 1.3 * math.sin(a))
        add_box(st, f"/World/Post{n}", (c[0] - 0.08, c[1] - 0.08, 0.0), (c[0] + 0.08, c[1] + 0.08, 0.5))
    light = UsdLux.SphereLight.Define(st, "/World/Light")
    light.CreateRadiusAttr(0.25)
    x = UsdGeom.XformCommonAPI(light)
    x.SetTranslate(Gf.Vec3d(0, 0, 1))
    x.SetRotate(Gf.Vec3f(0, 0, float(rotate_deg)))
    add_camera(st, "/World/Cam", (0, -0.01, 7), (0, 0, 0), focal=28.0)
    path = os.path.join(folder, (name or f"cube_ring_{rotate_deg:g}") + ".usda")
    st.GetRootLayer().Export(path)
    return path


def spread_stage(folder: str, half_angle_deg: float) -> str:
    """A sphere light (radius 0.1) 1 above a floor with a grid of posts, a camera straight above
    seeing the floor out to ``half_angle_deg`` off the light's downward axis (a square of half-side
    tan(angle)): the receivers a single frustum must hold open to that angle."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    reach = math.tan(math.radians(half_angle_deg))
    add_quad(st, "/World/Floor", (0, 0, 0), max(2.0 * reach, 2.0))
    step = max(reach / 4.0, 0.2)
    k = 0
    for gx in np.arange(-reach, reach + 1e-9, step):
        for gy in np.arange(-reach, reach + 1e-9, step):
            if abs(gx) < 0.15 and abs(gy) < 0.15:
                continue
            s = 0.04 + 0.02 * math.hypot(gx, gy)
            add_box(st, f"/World/Post{k}", (gx - s, gy - s, 0.0), (gx + s, gy + s, 0.3 + 0.05 * math.hypot(gx, gy)))
            k += 1
    light = UsdLux.SphereLight.Define(st, "/World/Light")
    light.CreateRadiusAttr(0.1)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(0, 0, 1))
    h = 6.0  # the camera's height; its half-width at the floor is ``reach``
    focal = 0.5 * 20.955 * h / reach
    add_camera(st, "/World/Cam", (0, -0.001, h), (0, 0, 0), focal=focal)
    path = os.path.join(folder, f"cube_spread_{half_angle_deg:g}.usda")
    st.GetRootLayer().Export(path)
    return path
