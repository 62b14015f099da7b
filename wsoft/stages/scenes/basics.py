"""The small bundled stages: ``box_plane`` (an exact answer known), ``contact``, ``multi_light``
(one light of each kind), ``cutout`` (an alpha-textured occluder) and ``penumbra_ramp``."""

from __future__ import annotations

import math
import os

import numpy as np
from pxr import Gf, UsdGeom, UsdLux

from wsoft.stages.builders import (
    add_cutout_material,
    add_material,
    add_mesh,
    add_rect_light,
    add_sphere_light,
    add_sun,
    check_points_down,
    look_at_xform,
    make_stage,
    mark_casters,
    set_doc_attr,
    set_doc_string,
)
from wsoft.stages.mesh import (
    MeshData,
    box_mesh,
    check_closed,
    prism_z,
    quad_mesh,
    torus_z,
    translate_mesh,
    triangle_count,
    uv_sphere_y,
)
from wsoft.stages.scenes import add_scene_camera
from wsoft.stages.textures import write_checker_png


def scene_box_plane(out_dir: str) -> dict[str, object]:
    """A square occluder parallel to a rect light over a plane, where the exact answer is known: ``box_plane.usda``."""
    path = os.path.join(out_dir, "box_plane.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    set_doc_attr(world, "wsoft:analytic:occluder_height", 1.0)
    set_doc_attr(world, "wsoft:analytic:light_height", 3.0)
    set_doc_attr(world, "wsoft:analytic:occluder_half", 1.0)
    set_doc_attr(world, "wsoft:analytic:light_half", 0.5)

    ground_mat = add_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8))
    occ_mat = add_material(stage, "/World/Looks/OccluderMat", (0.8, 0.25, 0.2))
    ground = quad_mesh([(-10, -10, 0), (10, -10, 0), (10, 10, 0), (-10, 10, 0)])
    occluder = quad_mesh([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)])
    add_mesh(stage, "/World/Ground", ground, False, ground_mat)
    add_mesh(stage, "/World/Occluder", occluder, True, occ_mat)

    light = add_rect_light(stage, "/World/Light", (0.0, 0.0, 3.0), 1.0, 1.0, intensity=10.0)  # identity rotation: emits -Z
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    add_scene_camera(stage, (0.0, -6.0, 9.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), clip=(0.1, 100.0))
    mark_casters(stage, ['/World/Occluder'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": triangle_count(ground[1]) + triangle_count(occluder[1])}


def scene_contact(out_dir: str) -> dict[str, object]:
    """Objects touching a Y-up ground (a cube, a sphere on its pole, a leaning plank): ``contact.usda``."""
    path = os.path.join(out_dir, "contact.usda")
    stage = make_stage("Y", path)
    tris = 0

    ground = quad_mesh([(-6, 0, 6), (6, 0, 6), (6, 0, -6), (-6, 0, -6)])  # faces +Y
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris += triangle_count(ground[1])

    # Unit cube, bottom face on y = 0, occupying x in [1, 2], z in [-0.5, 0.5].
    cube = box_mesh((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
    cube_prim = add_mesh(stage, "/World/Cube", cube, False,
                         add_material(stage, "/World/Looks/CubeMat", (0.2, 0.4, 0.8)))
    cube_prim.AddTranslateOp().Set(Gf.Vec3d(1.5, 0.5, 0.0))
    tris += triangle_count(cube[1])

    # Sphere of radius 0.6 whose bottom pole vertex touches y = 0.
    sphere = uv_sphere_y(0.6, 32, 16)
    sph = add_mesh(stage, "/World/Sphere", sphere, False,
                   add_material(stage, "/World/Looks/SphereMat", (0.85, 0.6, 0.2)))
    # float32(0.6) so the float32 pole vertex lands exactly on y = 0
    sph.AddTranslateOp().Set(Gf.Vec3d(-0.8, float(np.float32(0.6)), 1.1))
    tris += triangle_count(sphere[1])

    # Plank 3 x 0.1 x 0.5: local box x in [0, 3], y in [0, 0.1].  Its lower
    # bottom edge lies on the ground at x = P0 and its bottom face rests on
    # the cube's top edge (x = 1, y = 1) at distance s along the plank.
    length, thick, depth, s = 3.0, 0.1, 0.5, 2.2
    alpha = math.asin(1.0 / s)
    p0x = 1.0 - s * math.cos(alpha)
    plank = box_mesh((0.0, 0.0, -depth / 2), (length, thick, depth / 2))
    pl = add_mesh(stage, "/World/Plank", plank, False,
                  add_material(stage, "/World/Looks/PlankMat", (0.6, 0.45, 0.3)))
    pl.AddTranslateOp().Set(Gf.Vec3d(p0x, 0.0, 0.0))
    pl.AddRotateZOp(UsdGeom.XformOp.PrecisionDouble).Set(math.degrees(alpha))
    tris += triangle_count(plank[1])

    # RectLight above; rotateX(-90) maps local -Z to world -Y (down).
    light = add_rect_light(stage, "/World/Light", (1.0, 5.0, 1.0), 1.5, 1.5, intensity=10.0)
    light.AddRotateXOp().Set(-90.0)
    check_points_down(light.GetPrim(), (0, -1, 0), 0.999)

    add_scene_camera(stage, (0.5, 4.0, 7.0), (0.3, 0.4, 0.3), (0.0, 1.0, 0.0), clip=(0.1, 100.0))
    mark_casters(stage, ['/World/Cube', '/World/Sphere', '/World/Plank'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_multi_light(out_dir: str) -> dict[str, object]:
    """One light of each kind (one without shadows, a DomeLight) over n-gon occluders: ``multi_light.usda``."""
    path = os.path.join(out_dir, "multi_light.usda")
    stage = make_stage("Z", path)
    tris = 0

    def add(name: str, m: MeshData, color, double_sided=False):
        nonlocal tris
        mat = add_material(stage, "/World/Looks/%sMat" % name, color)
        add_mesh(stage, "/World/%s" % name, m, double_sided, mat)
        tris += triangle_count(m[1])

    add("Ground", quad_mesh([(-8, -8, 0), (8, -8, 0), (8, 8, 0), (-8, 8, 0)]), (0.8, 0.8, 0.8))
    stage.DefinePrim("/World/Occluders", "Xform")
    add("Occluders/BoxA", box_mesh((-3.5, -2.5, 0.0), (-2.5, -1.5, 1.0)), (0.7, 0.3, 0.3))
    add("Occluders/BoxB", box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 2.0)), (0.3, 0.7, 0.3))
    add("Occluders/FloatingBox", box_mesh((1.5, -2.8, 1.2), (2.7, -2.2, 1.5)), (0.3, 0.3, 0.7))
    # Hexagonal prism (hexagon faces kept as 6-gons), floating above ground.
    add("Occluders/HexPrism", prism_z(6, 0.7, 1.2, 2.0, center=(-2.0, 2.0)), (0.8, 0.7, 0.2))
    # Pentagonal prism standing on the ground.
    add("Occluders/PentPrism", prism_z(5, 0.5, 0.0, 1.4, center=(0.0, -3.5), phase=math.pi / 2),
        (0.6, 0.3, 0.7))
    # Cylinder with 16-gon caps.
    add("Occluders/Cylinder", prism_z(16, 0.4, 0.0, 1.6, center=(3.5, 0.5)), (0.2, 0.6, 0.7))
    # Quad torus lying flat, floating.
    add("Occluders/Torus", translate_mesh(torus_z(1.0, 0.25, 32, 12), (2.0, 3.0, 1.0)),
        (0.75, 0.5, 0.35))

    stage.DefinePrim("/World/Lights", "Xform")
    rect = add_rect_light(stage, "/World/Lights/Rect", look_at_xform((-2.5, -1.0, 5.0), (-2.5, -1.5, 0.0), (0, 1, 0)), 1.2, 0.8,
                          intensity=20.0)
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.9)

    disk = UsdLux.DiskLight.Define(stage, "/World/Lights/Disk")
    disk.CreateRadiusAttr(0.5)
    disk.CreateIntensityAttr(20.0)
    disk.AddTransformOp().Set(look_at_xform((2.5, -1.0, 4.5), (2.0, -2.5, 0.0), (0, 1, 0)))
    check_points_down(disk.GetPrim(), (0, 0, -1), 0.9)

    add_sphere_light(stage, "/World/Lights/Sphere", (-1.5, 2.5, 3.5), 0.3, 30.0)

    sun = add_sun(stage, "/World/Lights/Sun", 2.0, (35.0, 0.0, 30.0), intensity=2.0)
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)

    noshadow = add_sphere_light(stage, "/World/Lights/NoShadow", (3.0, 2.0, 2.5), 0.2, 10.0)
    UsdLux.ShadowAPI.Apply(noshadow.GetPrim()).CreateShadowEnableAttr(False)

    dome = UsdLux.DomeLight.Define(stage, "/World/Lights/Dome")
    dome.CreateIntensityAttr(0.2)

    add_scene_camera(stage, (0.0, -11.0, 9.0), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_cutout(out_dir: str) -> dict[str, object]:
    """An occluder perforated by an alpha checker texture, and an opaque box: ``cutout.usda``."""
    path = os.path.join(out_dir, "cutout.usda")
    write_checker_png(os.path.join(out_dir, "textures", "checker_alpha.png"))
    stage = make_stage("Z", path)
    tris = 0

    ground = quad_mesh([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)])
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris += triangle_count(ground[1])

    # Cutout material: opacity <- texture alpha, opacityThreshold 0.5.
    mat = add_cutout_material(stage, "/World/Looks/FenceMat", (0.9, 0.47, 0.16), "textures/checker_alpha.png",
                              rgb_output=True)

    fence = quad_mesh([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)])
    add_mesh(stage, "/World/Fence", fence, True, mat, st=[(0, 0), (1, 0), (1, 1), (0, 1)])
    tris += triangle_count(fence[1])

    leaf = box_mesh((2.0, -0.5, 0.6), (3.0, 0.5, 1.2))
    add_mesh(stage, "/World/Leaf", leaf, False,
             add_material(stage, "/World/Looks/LeafMat", (0.3, 0.6, 0.25)))
    tris += triangle_count(leaf[1])

    light = add_rect_light(stage, "/World/Light", (0.0, 0.0, 4.0), 0.5, 0.5, intensity=20.0)
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    add_scene_camera(stage, (0.5, -2.5, 8.0), (0.5, 0.0, 0.0), (0.0, 0.0, 1.0), aspect="1:1",
                     clip=(0.1, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# (x, z) of the plate centres: penumbra width on the ground grows with z.
PENUMBRA_PLATES = [(-6.0, 0.25), (-3.0, 0.75), (0.0, 1.5), (3.0, 2.5), (6.0, 3.5)]
PENUMBRA_LIGHT_Z = 6.0
PENUMBRA_LIGHT_SIZE = 1.5
PENUMBRA_PLATE_SIZE = 0.8
PENUMBRA_PLATE_THICK = 0.05


def scene_penumbra_ramp(out_dir: str) -> dict[str, object]:
    """Five plates at growing heights under a rect light, penumbra widths 0.07 to 2.1: ``penumbra_ramp.usda``."""
    path = os.path.join(out_dir, "penumbra_ramp.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    L, s, hs, ht = PENUMBRA_LIGHT_Z, PENUMBRA_LIGHT_SIZE, PENUMBRA_PLATE_SIZE / 2, PENUMBRA_PLATE_THICK / 2
    widths = ", ".join("z=%g: %.4g" % (z, s * z / (L - z)) for _, z in PENUMBRA_PLATES)
    shadow_x = [x * L / (L - z) for x, z in PENUMBRA_PLATES]
    # Ground: 16 x 16 around the middle, extended in +X so that the shadow of
    # the highest plate (x = 6, z = 3.5), which falls around x = 14.4, is on it.
    gx0, gx1, gy = -8.0, 18.0, 8.0
    set_doc_string(world, "wsoft:doc", (
        "Penumbra-width ramp. Five 0.8 x 0.8 x 0.05 square plates (closed boxes) in a row at "
        "y = 0, centred at x = -6, -3, 0, 3, 6 and heights z = 0.25, 0.75, 1.5, 2.5, 3.5, under "
        "one 1.5 x 1.5 RectLight at (0, 0, 6) emitting straight down onto a single-sided ground "
        "at z = 0 spanning x in [%g, %g], y in [%g, %g]. All planes are parallel, so each plate's "
        "shadow is the plate scaled by 6 / (6 - z) about the light point, and its penumbra "
        "width on the ground is 1.5 * z / (6 - z) (plate thickness ignored): %s. Shadow centres "
        "at x = %s. Tests that a soft-shadow technique widens the penumbra with the "
        "occluder-receiver distance (PCSS-style blocker search) and stays sharp near contact."
        % (gx0, gx1, -gy, gy, widths, ", ".join("%.3g" % v for v in shadow_x))))

    ground = quad_mesh([(gx0, -gy, 0), (gx1, -gy, 0), (gx1, gy, 0), (gx0, gy, 0)])
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris = triangle_count(ground[1])

    plate_mat = add_material(stage, "/World/Looks/PlateMat", (0.8, 0.3, 0.2))
    stage.DefinePrim("/World/Plates", "Xform")
    for k, (x, z) in enumerate(PENUMBRA_PLATES):
        plate = box_mesh((x - hs, -hs, z - ht), (x + hs, hs, z + ht))
        check_closed(plate, "Plate%d" % k)
        add_mesh(stage, "/World/Plates/Plate%d" % k, plate, False, plate_mat)
        tris += triangle_count(plate[1])

    light = add_rect_light(stage, "/World/Light", (0.0, 0.0, L), s, s, intensity=10.0)  # identity rotation: emits -Z
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    add_scene_camera(stage, (5.0, -15.0, 12.0), (5.0, 0.0, 0.6), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    mark_casters(stage, ['/World/Plates'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
