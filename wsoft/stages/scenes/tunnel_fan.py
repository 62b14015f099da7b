"""``tunnel_fan``: a fan at the end of a tunnel under a point light just beyond it, for irregular
z-buffer shadows (Galoppo, Fig. 1.6.11): receivers nearly parallel to both the eye and the light
directions, the hard case for shadow maps."""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.stages.builders import add_material, add_mesh, add_point_light, make_stage, set_doc_string
from wsoft.stages.mesh import (
    MeshData,
    box_mesh,
    check_closed,
    face_normals,
    grid_quad_mesh,
    merge_meshes,
    prism_z,
    translate_mesh,
    triangle_count,
)
from wsoft.stages.scenes import add_scene_camera


TUNNEL_LENGTH = 12.0
TUNNEL_HALF = 1.0  # square cross-section y in [-1, 1], z in [0, 2]; axis at y = 0, z = 1
TUNNEL_CELL = 0.25  # grid spacing of the walls
FAN_X = 11.8  # plane of the blades' centres, inside the open end
FAN_BLADES = 6
FAN_BLADE = (0.08, 0.98, 0.06, 0.25, 0.02)  # root and tip radius, root and tip width, thickness
FAN_PITCH = 25.0  # degrees: each blade is turned about its own radial axis
FAN_PHASE = 15.0  # degrees: angle of blade 0 from +Y
FAN_HUB = (0.1, 0.2, 12)  # radius, length along X, sides
TUNNEL_LIGHT = (13.5, 0.0, 1.0)


def fan_blade(k: int) -> MeshData:
    """Blade k: a thin closed tapered box along its radial axis in the plane x = FAN_X, from
    the root to the tip radius, its width growing linearly from the root to the tip, with its
    chord turned by FAN_PITCH about the radial axis out of that plane (8 points, 6 quads)."""
    r0, r1, w0, w1, t = FAN_BLADE
    th = math.radians(FAN_PHASE + 360.0 * k / FAN_BLADES)
    p = math.radians(FAN_PITCH)
    e_x = np.array([1.0, 0.0, 0.0])
    e_r = np.array([0.0, math.cos(th), math.sin(th)])
    e_t = np.array([0.0, -math.sin(th), math.cos(th)])  # e_r x e_t = e_x
    chord = math.cos(p) * e_t + math.sin(p) * e_x
    normal = -math.sin(p) * e_t + math.cos(p) * e_x  # (chord, normal, e_r) right-handed
    hub = np.array([FAN_X, 0.0, TUNNEL_HALF])
    pts = np.empty((8, 3), dtype=np.float64)
    for i in range(8):  # box_mesh's order: bit 0 -> chord, bit 1 -> normal, bit 2 -> radius
        r, w = (r1, w1) if i & 4 else (r0, w0)
        pts[i] = (hub + r * e_r + (0.5 * w if i & 1 else -0.5 * w) * chord
                  + (0.5 * t if i & 2 else -0.5 * t) * normal)
    _, counts, idx = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    return pts, counts, idx


def scene_tunnel_fan(out_dir: str) -> dict[str, object]:
    """The open tunnel of inward-facing grids, the fan and the point light beyond it: ``tunnel_fan.usda``."""
    path = os.path.join(out_dir, "tunnel_fan.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    L, h = TUNNEL_LENGTH, TUNNEL_HALF
    nl, nw = int(round(L / TUNNEL_CELL)), int(round(2 * h / TUNNEL_CELL))
    tris = 0

    # Single-sided surfaces, wound so that their normals face into the tunnel.
    stage.DefinePrim("/World/Tunnel", "Xform")
    floor_mat = add_material(stage, "/World/Looks/FloorMat", (0.75, 0.73, 0.7))
    wall_mat = add_material(stage, "/World/Looks/WallMat", (0.7, 0.72, 0.78))
    surfaces = [
        ("Floor", grid_quad_mesh((0, -h, 0), (L, 0, 0), (0, 2 * h, 0), nl, nw), floor_mat),
        ("Ceiling", grid_quad_mesh((0, h, 2 * h), (L, 0, 0), (0, -2 * h, 0), nl, nw), wall_mat),
        ("WallRight", grid_quad_mesh((0, -h, 0), (0, 0, 2 * h), (L, 0, 0), nw, nl), wall_mat),
        ("WallLeft", grid_quad_mesh((0, h, 0), (L, 0, 0), (0, 0, 2 * h), nl, nw), wall_mat),
    ]
    inward = {"Floor": (0, 0, 1), "Ceiling": (0, 0, -1),
              "WallRight": (0, 1, 0), "WallLeft": (0, -1, 0)}
    for name, m, mat in surfaces:
        if not np.allclose(face_normals(m), inward[name]):
            raise RuntimeError("Tunnel/%s: normals do not face into the tunnel" % name)
        add_mesh(stage, "/World/Tunnel/" + name, m, False, mat)
        tris += triangle_count(m[1])

    stage.DefinePrim("/World/Fan", "Xform")
    fan_mat = add_material(stage, "/World/Looks/FanMat", (0.25, 0.3, 0.35), roughness=0.4)
    hr, hl, hn = FAN_HUB
    hub = prism_z(hn, hr, -0.5 * hl, 0.5 * hl)
    # (x, y, z) -> (z, x, y) is a rotation (a cyclic permutation): the prism's axis becomes X
    hub = translate_mesh((hub[0][:, [2, 0, 1]], hub[1], hub[2]), (FAN_X, 0.0, h))
    check_closed(hub, "Fan/Hub")
    add_mesh(stage, "/World/Fan/Hub", hub, False, fan_mat)
    tris += triangle_count(hub[1])
    blades = merge_meshes([fan_blade(k) for k in range(FAN_BLADES)])
    check_closed(blades, "Fan/Blades")
    add_mesh(stage, "/World/Fan/Blades", blades, False, fan_mat)
    tris += triangle_count(blades[1])

    add_point_light(stage, "/World/Light", TUNNEL_LIGHT, intensity=60.0, radius=0.0)
    r0, r1, w0, w1, t = FAN_BLADE
    set_doc_string(world, "wsoft:doc", (
        "Fan at the end of a tunnel, for irregular z-buffer (Galoppo, 'Eye-View Pixel "
        "Anti-Aliasing for Irregular Shadow Mapping', fig. 1.6.11): the walls are nearly "
        "parallel to both the eye and the light directions, the hard case for shadow maps. "
        "The tunnel runs along +X from x = 0 to %g with a square cross-section y in [-%g, %g], "
        "z in [0, %g], open at both ends: single-sided floor, ceiling and walls "
        "(/World/Tunnel/*, grids of %g x %g quads) whose normals face inward. The fan "
        "(/World/Fan) in the plane x = %g on the axis (y = 0, z = %g): a %d-sided hub "
        "(radius %g, length %g along X) and %d closed tapered blades (radius %g to %g, width "
        "%g at the root to %g at the tip, thickness %g, pitched %g deg about their radial "
        "axes; the tapering keeps lit gaps between the blades' shadows near the hub). The "
        "light /World/Light is a point light (SphereLight, radius 0, treatAsPoint) at (%g, %g, %g), just beyond the "
        "fan on the axis, so the blades' shadows stream along the inside walls at grazing "
        "angles toward the camera near x = 0.5."
        % ((L, h, h, 2 * h, TUNNEL_CELL, TUNNEL_CELL, FAN_X, h, hn, hr, hl, FAN_BLADES, r0, r1,
            w0, w1, t, FAN_PITCH) + TUNNEL_LIGHT)))

    add_scene_camera(stage, (0.5, 0.3, 1.25), (12.0, -0.15, 0.9), (0.0, 0.0, 1.0), clip=(0.05, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
