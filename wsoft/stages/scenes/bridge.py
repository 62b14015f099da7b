"""``lightmapped_bridge``: the setting of Salzman's "Simpler Soft Shadow Mapping": a static world
with baked per-vertex lighting (:mod:`wsoft.stages.bake_light`) and dynamic prims that need
real-time shadows (a walking character and a ball on a bridge), a sun above and a torch below."""

from __future__ import annotations

import os

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, Vt

from wsoft.stages.bake_light import bake_vertex_irradiance
from wsoft.stages.builders import (
    add_material,
    add_mesh,
    add_sun,
    check_points_down,
    make_stage,
    set_custom_bool,
    set_display_color,
    set_doc_string,
    world_dir,
)
from wsoft.stages.mesh import MeshData, box_mesh, check_closed, grid_box_mesh, grid_quad_mesh, triangle_count, z_sphere
from wsoft.stages.scenes import add_scene_camera


BRIDGE_STATIC_BOXES = [
    # (name, lo, hi, color)
    ("BridgeDeck", (-6.0, -1.5, 2.6), (6.0, 1.5, 3.0), (0.55, 0.42, 0.3)),
    ("PillarWest", (-5.4, -1.0, 0.0), (-4.6, 1.0, 2.6), (0.5, 0.5, 0.48)),
    ("PillarEast", (4.6, -1.0, 0.0), (5.4, 1.0, 2.6), (0.5, 0.5, 0.48)),
    ("Crate", (1.6, 0.2, 0.0), (2.4, 1.0, 0.8), (0.6, 0.45, 0.25)),
    ("BoxA", (-10.0, 3.0, 0.0), (-8.5, 4.5, 1.5), (0.45, 0.55, 0.7)),
    ("BoxB", (8.0, -6.0, 0.0), (10.0, -4.5, 1.0), (0.7, 0.5, 0.45)),
    ("BoxC", (9.0, 4.0, 0.0), (10.5, 7.0, 2.5), (0.5, 0.65, 0.45)),
]
BRIDGE_CELL = 0.25  # target grid spacing of the static boxes' faces
BRIDGE_TORCH = (0.0, 0.0, 1.2)
BRIDGE_FRAMES = (1, 48)


def humanoid_parts() -> list[tuple[str, MeshData]]:
    """Boxes of a ~1.8 tall figure facing +X, feet on z = 0, centred on x = y = 0."""
    return [
        ("LegLeft", box_mesh((-0.09, 0.03, 0.0), (0.09, 0.19, 0.85))),
        ("LegRight", box_mesh((-0.09, -0.19, 0.0), (0.09, -0.03, 0.85))),
        ("Torso", box_mesh((-0.12, -0.22, 0.85), (0.12, 0.22, 1.47))),
        ("ArmLeft", box_mesh((-0.07, 0.23, 0.8), (0.07, 0.33, 1.44))),
        ("ArmRight", box_mesh((-0.07, -0.33, 0.8), (0.07, -0.23, 1.44))),
        ("Head", box_mesh((-0.11, -0.11, 1.5), (0.11, 0.11, 1.8))),
    ]


def scene_lightmapped_bridge(out_dir: str) -> dict[str, object]:
    """The baked static world, the walking character and the ball: ``lightmapped_bridge.usda``."""
    path = os.path.join(out_dir, "lightmapped_bridge.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    f0, f1 = BRIDGE_FRAMES
    stage.SetStartTimeCode(f0)
    stage.SetEndTimeCode(f1)
    stage.SetTimeCodesPerSecond(24.0)
    tris = 0

    # Lights first: the bake reads their world transforms.
    stage.DefinePrim("/World/Lights", "Xform")
    sun = add_sun(stage, "/World/Lights/Sun", 1.5, (18.0, 0.0, 117.0), intensity=1.0)
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.9)
    sun_dir = world_dir(sun.GetPrim())

    torch = UsdLux.SphereLight.Define(stage, "/World/Lights/Torch")
    torch.CreateRadiusAttr(0.15)
    torch.CreateIntensityAttr(30.0)
    torch_color = (1.0, 0.62, 0.3)
    torch.CreateColorAttr(Gf.Vec3f(*torch_color))
    torch.AddTranslateOp().Set(Gf.Vec3d(*BRIDGE_TORCH))
    set_custom_bool(torch.GetPrim(), "wsoft:torch", True)

    bake_lights = [
        {"kind": "distant", "to_light": [-sun_dir[0], -sun_dir[1], -sun_dir[2]],
         "intensity": 1.0, "color": (1.0, 1.0, 1.0)},
        {"kind": "sphere", "position": BRIDGE_TORCH, "radius": 0.15,
         "intensity": 30.0, "color": torch_color},
    ]
    boxes = [(lo, hi) for _, lo, hi, _ in BRIDGE_STATIC_BOXES]
    deck_lo, deck_hi = BRIDGE_STATIC_BOXES[0][1], BRIDGE_STATIC_BOXES[0][2]
    if not (0.0 + 0.15 < BRIDGE_TORCH[2] < deck_lo[2] - 0.15):
        raise RuntimeError("torch must sit between the riverbed and the deck underside")

    # Static world with baked per-vertex irradiance.
    stage.DefinePrim("/World/Static", "Xform")

    def add_static(name: str, m: MeshData, color) -> None:
        nonlocal tris
        mesh = add_mesh(stage, "/World/Static/%s" % name, m, False,
                        add_material(stage, "/World/Looks/%sMat" % name, color))
        set_display_color(mesh, color)
        baked = bake_vertex_irradiance(m, bake_lights, boxes)
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "wsoft:bakedLight", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
        pv.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(baked, dtype=np.float32)))
        tris += triangle_count(m[1])

    add_static("Ground", grid_quad_mesh((-15.0, -15.0, 0.0), (30.0, 0.0, 0.0),
                                        (0.0, 30.0, 0.0), 60, 60), (0.45, 0.42, 0.35))
    for name, lo, hi, color in BRIDGE_STATIC_BOXES:
        n = [max(1, int(round((hi[k] - lo[k]) / BRIDGE_CELL))) for k in range(3)]
        m = grid_box_mesh(lo, hi, n)
        check_closed(m, name)
        add_static(name, m, color)

    # Dynamic objects: not in the bake; they need real-time shadows.
    stage.DefinePrim("/World/Dynamic", "Xform")
    char = UsdGeom.Xform.Define(stage, "/World/Dynamic/Character")
    set_custom_bool(char.GetPrim(), "wsoft:dynamic", True)
    walk = char.AddTranslateOp()
    for t in range(f0, f1 + 1):
        x = -4.0 + 8.0 * (t - f0) / (f1 - f0)
        walk.Set(Gf.Vec3d(round(x, 6), 0.0, deck_hi[2]), Usd.TimeCode(t))
    body_color = (0.25, 0.35, 0.75)
    body_mat = add_material(stage, "/World/Looks/CharacterMat", body_color)
    for name, m in humanoid_parts():
        check_closed(m, name)
        mesh = add_mesh(stage, "/World/Dynamic/Character/%s" % name, m, False, body_mat)
        set_display_color(mesh, body_color)
        tris += triangle_count(m[1])

    ball_r, ball_color = 0.4, (0.85, 0.2, 0.2)
    ball = z_sphere(ball_r, 24, 12)
    check_closed(ball, "Ball")
    bmesh = add_mesh(stage, "/World/Dynamic/Ball", ball, False,
                     add_material(stage, "/World/Looks/BallMat", ball_color))
    # float32(r) so the float32 bottom pole vertex lands exactly on the deck top
    bmesh.AddTranslateOp().Set(Gf.Vec3d(2.5, 0.9, deck_hi[2] + float(np.float32(ball_r))))
    set_display_color(bmesh, ball_color)
    set_custom_bool(bmesh.GetPrim(), "wsoft:dynamic", True)
    tris += triangle_count(ball[1])

    set_doc_string(world, "wsoft:doc", (
        "Lightmapped world with a dynamic character, after Salzman's 'Simpler Soft Shadow "
        "Mapping'. Static meshes under /World/Static (riverbed ground 30 x 30 at z = 0, a "
        "12 x 3 x 0.4 bridge deck with its top at z = 3 on two pillars, a crate under the "
        "bridge and three boxes) carry baked lighting in the vertex-interpolated color3f "
        "primvar 'primvars:wsoft:bakedLight': per-vertex irradiance 0.05 (ambient) + sum over "
        "/World/Lights/Sun and /World/Lights/Torch of color * weight * max(0, n.l) * falloff * "
        "visibility, with sun weight = intensity, falloff 1, and torch weight = intensity * pi * "
        "r^2, falloff 1 / d^2 (each light as a point at its centre), visibility from "
        "segment-vs-box tests against the static boxes only, averaged over the face corners "
        "at each vertex. Dynamic prims are marked with the custom bool 'wsoft:dynamic = true': "
        "/World/Dynamic/Character (box humanoid, 1.8 tall, time-sampled translate walking "
        "along X on the deck from x = -4 at time 1 to x = 4 at time 48, 24 tcps) and "
        "/World/Dynamic/Ball (r 0.4, static transform, resting on the deck). They are not in "
        "the bake and need real-time shadows from both lights. The torch is "
        "/World/Lights/Torch (SphereLight r 0.15 at (0, 0, 1.2) under the deck, custom bool "
        "'wsoft:torch = true'); the sun is /World/Lights/Sun (DistantLight, angle 1.5 deg, "
        "slanted). The riverbed under the deck is in the deck's sun shadow and lit mainly by "
        "the torch."))

    add_scene_camera(stage, (-2.5, -10.5, 4.6), (0.0, 0.0, 1.9), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
