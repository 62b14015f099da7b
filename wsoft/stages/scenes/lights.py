"""Stages lit as production sets light them: the sky (a DomeLight), spots with cones and an IES
profile, and a sun that matches the sky (``dome_uniform.usda``, ``dusk_street.usda``).

The dusk sky is procedural (:func:`dusk_sky`, no downloaded image): a latlong image in OpenEXR's
layout (:mod:`wsoft.scene.dome`) written as a Radiance ``.hdr`` (:func:`wsoft.rgbe.write_rgbe`),
its sun one texel whose centre the stage's DistantLight points from.
"""

from __future__ import annotations

import math
import os
import shutil

import numpy as np
from pxr import Sdf, UsdGeom, UsdLux

from wsoft.rgbe import write_rgbe
from wsoft.stages.builders import add_material, add_mesh, add_sphere_light, add_sun, make_stage, set_doc_string
from wsoft.stages.mesh import box_mesh, merge_meshes, quad_mesh, triangle_count
from wsoft.stages.scenes import add_scene_camera

SKY_HEIGHT = 64  # the dusk sky's latlong image: 128 x 64 texels (about 2.8 degrees each)
SUN_TEXEL = (29, 40)  # its sun's texel (row, column): latitude 7.0, longitude 66.1 degrees in the dome's frame
POLE_ON_Z = 90.0  # rotateX of a DomeLight on a Z-up stage: its +Y pole onto +Z (+Z onto -Y)
IES_PROFILE = "wsoft_downlight.ies"  # the bundled example profile (usd_scenes/ies, wsoft.scene.ies.EXAMPLE)


def dome_to_world(q: np.ndarray) -> np.ndarray:
    """Directions in the dome's frame (``[..., 3]``) in a Z-up world, the dome turned by rotateX(:data:`POLE_ON_Z`)."""
    return np.stack([q[..., 0], -q[..., 2], q[..., 1]], axis=-1)


def texel_centres(h: int) -> np.ndarray:
    """The centre direction of every texel of an ``h x 2h`` latlong image in the dome's frame, ``[h, 2h, 3]``."""
    lat = 0.5 * math.pi - math.pi * (np.arange(h) + 0.5) / h
    lon = math.pi - 2.0 * math.pi * (np.arange(2 * h) + 0.5) / (2 * h)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    return np.stack([np.cos(la) * np.sin(lo), np.sin(la), np.cos(la) * np.cos(lo)], axis=-1)


def dusk_sky(h: int = SKY_HEIGHT, sun=SUN_TEXEL) -> tuple[np.ndarray, np.ndarray]:
    """A dusk sky as a latlong radiance image ``[h, 2h, 3]`` (float32, row 0 the zenith) and the
    world direction (Z up) toward its sun (the centre of texel ``sun``, its brightest texel). Above
    the horizon a deep blue zenith fades into an orange horizon (``(1 - elevation)^3``) with a glow
    about the sun (``exp(-angle / 0.25 rad)``); below it a dark ground."""
    q = texel_centres(h)
    w = dome_to_world(q)
    s = w[sun]
    e = w[..., 2]
    gamma = np.arccos(np.clip(w @ s, -1.0, 1.0))
    zenith, horizon = np.array([0.06, 0.09, 0.22]), np.array([0.95, 0.5, 0.25])
    t = (1.0 - np.clip(e, 0.0, 1.0))[..., None] ** 3
    sky = zenith * (1.0 - t) + horizon * t + np.array([1.0, 0.45, 0.15]) * 1.5 * np.exp(-gamma / 0.25)[..., None]
    ground = np.array([0.05, 0.04, 0.035]) + 0.2 * horizon * np.exp(np.minimum(e, 0.0) / 0.05)[..., None]
    img = np.where((e > 0.0)[..., None], sky, ground)
    img[sun] = (400.0, 240.0, 140.0)
    return img.astype(np.float32), s / np.linalg.norm(s)


def _dome(stage, path: str, texture: str | None = None, intensity: float = 1.0) -> UsdLux.DomeLight:
    """A DomeLight turned pole-up onto +Z; ``texture``: its latlong ``inputs:texture:file``."""
    dome = UsdLux.DomeLight.Define(stage, path)
    dome.CreateIntensityAttr(float(intensity))
    UsdGeom.Xformable(dome).AddRotateXOp().Set(POLE_ON_Z)
    if texture is not None:
        dome.CreateTextureFileAttr(Sdf.AssetPath(texture))
        dome.CreateTextureFormatAttr("latlong")
    return dome


def _spot(stage, path: str, pos, cone: float, *, softness: float = 0.0, ies: str | None = None, intensity: float = 80.0):
    """A small sphere light at ``pos`` facing down with ``UsdLux.ShapingAPI``: a ``cone`` (degrees),
    ``softness``, and the IES profile ``ies`` where given."""
    light = add_sphere_light(stage, path, pos, 0.08, intensity)
    light.CreateColorAttr((1.0, 0.85, 0.6))
    api = UsdLux.ShapingAPI.Apply(light.GetPrim())
    api.CreateShapingConeAngleAttr(float(cone))
    if softness:
        api.CreateShapingConeSoftnessAttr(float(softness))
    if ies is not None:
        api.CreateShapingIesFileAttr(Sdf.AssetPath(ies))
    return light


def scene_dome_uniform(out_dir: str) -> dict[str, object]:
    """A box and a small table on a ground under a constant DomeLight: ``dome_uniform.usda``."""
    path = os.path.join(out_dir, "dome_uniform.usda")
    stage = make_stage("Z", path)
    ground = quad_mesh([(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)])
    box = box_mesh((-1.6, -0.5, 0.0), (-0.6, 0.5, 1.0))
    legs = [box_mesh((x - 0.04, y - 0.04, 0.0), (x + 0.04, y + 0.04, 0.7)) for x in (0.6, 1.9) for y in (-0.4, 0.4)]
    table = merge_meshes([box_mesh((0.5, -0.5, 0.7), (2.0, 0.5, 0.76)), *legs])
    add_mesh(stage, "/World/Ground", ground, False, add_material(stage, "/World/Looks/Ground", (0.8, 0.8, 0.8)))
    add_mesh(stage, "/World/Box", box, False, add_material(stage, "/World/Looks/Box", (0.75, 0.35, 0.25)))
    add_mesh(stage, "/World/Table", table, False, add_material(stage, "/World/Looks/Table", (0.55, 0.45, 0.35)))
    _dome(stage, "/World/Sky")
    add_scene_camera(stage, (2.5, -6.0, 4.5), (0.2, 0.0, 0.3), (0.0, 0.0, 1.0), clip=(0.1, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": triangle_count(ground[1]) + triangle_count(box[1]) + triangle_count(table[1])}


def scene_dusk_street(out_dir: str) -> dict[str, object]:
    """A street at dusk: buildings, lamp posts, a bench and a car under a textured sky (its HDR
    written here), a sun from the sky's brightest texel and two spots (30 degrees, soft; 60 degrees
    with the bundled IES profile): ``dusk_street.usda``."""
    from wsoft.usd_scenes import folder as bundled_folder

    path = os.path.join(out_dir, "dusk_street.usda")
    os.makedirs(os.path.join(out_dir, "textures"), exist_ok=True)
    sky, sun_dir = dusk_sky()
    write_rgbe(os.path.join(out_dir, "textures", "dusk_sky.hdr"), sky)
    ies_dir = os.path.join(out_dir, "ies")
    src = os.path.join(str(bundled_folder()), "ies", IES_PROFILE)
    if os.path.abspath(os.path.join(ies_dir, IES_PROFILE)) != os.path.abspath(src):
        os.makedirs(ies_dir, exist_ok=True)
        shutil.copyfile(src, os.path.join(ies_dir, IES_PROFILE))

    stage = make_stage("Z", path)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc",
                   "dusk street: DomeLight textures/dusk_sky.hdr (procedural), Sun from its brightest texel, "
                   "Spot30 (soft cone) and Spot60 (IES profile)")
    tris = 0

    def add(name, m, color):
        nonlocal tris
        add_mesh(stage, f"/World/{name}", m, False, add_material(stage, f"/World/Looks/{name}", color))
        tris += triangle_count(m[1])

    add("Street", quad_mesh([(-12, -8, 0), (12, -8, 0), (12, 8, 0), (-12, 8, 0)]), (0.35, 0.35, 0.37))
    add("Sidewalk", merge_meshes([box_mesh((-12, 3.0, 0), (12, 4.5, 0.15)), box_mesh((-12, -4.5, 0), (12, -3.0, 0.15))]),
        (0.6, 0.58, 0.55))
    heights = (6.0, 9.0, 4.5, 7.5, 5.0)
    north = [box_mesh((-12 + 4.8 * i + 0.2, 4.5, 0), (-12 + 4.8 * (i + 1) - 0.2, 8.0, heights[i])) for i in range(5)]
    south = [box_mesh((-12 + 4.8 * i + 0.2, -8.0, 0), (-12 + 4.8 * (i + 1) - 0.2, -4.5, heights[(i + 2) % 5] * 0.8)) for i in range(5)]
    add("BuildingsNorth", merge_meshes(north), (0.7, 0.6, 0.5))
    add("BuildingsSouth", merge_meshes(south), (0.55, 0.6, 0.7))
    posts = [box_mesh((x - 0.06, y - 0.06, 0.15), (x + 0.06, y + 0.06, 4.3)) for x, y in ((-3.0, -3.6), (3.5, 3.6))]
    arms = [box_mesh((-3.06, -3.66, 4.3), (-3.06 + 0.06, -1.5, 4.38)), box_mesh((3.44, 1.5, 4.3), (3.56, 3.66, 4.38))]
    add("LampPosts", merge_meshes(posts + arms), (0.15, 0.15, 0.17))
    add("Bench", merge_meshes([box_mesh((-4.2, -2.9, 0.45), (-1.8, -2.4, 0.52)),
                               *[box_mesh((x, -2.85, 0.0), (x + 0.08, -2.45, 0.45)) for x in (-4.1, -1.98)]]), (0.45, 0.3, 0.2))
    add("Car", merge_meshes([box_mesh((0.5, -1.0, 0.3), (4.5, 0.8, 1.1)), box_mesh((1.4, -0.9, 1.1), (3.4, 0.7, 1.7))]),
        (0.6, 0.1, 0.1))

    _dome(stage, "/World/Lights/Sky", "textures/dusk_sky.hdr", intensity=1.0)
    sun = add_sun(stage, "/World/Lights/Sun", 0.53, intensity=3.0, toward=sun_dir)
    sun.CreateColorAttr((1.0, 0.6, 0.35))
    _spot(stage, "/World/Lights/Spot30", (-3.0, -1.6, 4.2), 30.0, softness=0.4)
    _spot(stage, "/World/Lights/Spot60", (3.5, 1.6, 4.2), 60.0, ies=f"ies/{IES_PROFILE}")
    add_scene_camera(stage, (-10.5, -2.4, 3.4), (3.0, 0.8, 0.6), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
