"""Interiors lit from inside: ``room_lamp`` (a sphere light hanging in a furnished closed room) and
``corridor_torch`` (a small sphere light in a long closed corridor with pillars). Receivers lie
all around each light (floor, ceiling and walls, behind, beside and above it), so no single
frustum of a light view holds them: the scenes of omnidirectional (cube-map) shadows."""

from __future__ import annotations

import math
import os

from wsoft.stages.builders import add_material, add_mesh, add_sphere_light, make_stage, set_doc_string
from wsoft.stages.mesh import (
    MeshData,
    bar_mesh,
    box_mesh,
    check_closed,
    grid_box_mesh,
    merge_meshes,
    translate_mesh,
    triangle_count,
    z_sphere,
)
from wsoft.stages.scenes import add_scene_camera

SHELL_THICK = 0.1  # walls, floor and ceiling are closed slabs this thick
SHELL_CELL = 0.5  # grid spacing of the slabs' faces

ROOM = (5.0, 4.0, 2.8)  # inside: x in [0, 5], y in [0, 4], z in [0, 2.8]
ROOM_LAMP = (2.6, 2.1, 2.05)
ROOM_LAMP_RADIUS = 0.12
ROOM_CAMERA = ((0.35, 0.3, 1.75), (4.6, 3.7, 1.15))  # eye, target: a corner looking at the opposite one
ROOM_FOCAL = 12.0  # mm on the 36 x 27 mm aperture: 113 x 97 degrees

CORRIDOR = (24.0, 3.0, 3.0)  # inside: x in [0, 24], y in [-1.5, 1.5], z in [0, 3]
CORRIDOR_PILLARS = [3.0 * k for k in range(1, 8)]  # x of each pillar pair: 3 .. 21
CORRIDOR_PILLAR = (0.3, 1.05)  # side, |y| of the centre (a 0.3 gap to the wall behind it)
CORRIDOR_TORCH = (5.5, 0.45, 2.1)
CORRIDOR_TORCH_RADIUS = 0.03
CORRIDOR_CAMERA = ((0.6, -0.55, 1.6), (24.0, 0.3, 1.25))
CORRIDOR_FOCAL = 24.0  # mm on 36 x 27: 74 x 59 degrees


def shell(inside_lo, inside_hi, thick: float = SHELL_THICK, cell: float = SHELL_CELL) -> dict[str, MeshData]:
    """The six closed slabs around the box ``inside_lo .. inside_hi`` (floor and ceiling over the
    whole footprint with the walls' thickness, walls between them), their faces grids of about
    ``cell``: name -> mesh. They touch without gaps, so no light leaves the box."""
    x0, y0, z0 = map(float, inside_lo)
    x1, y1, z1 = map(float, inside_hi)
    t = float(thick)
    slabs = {
        "Floor": ((x0 - t, y0 - t, z0 - t), (x1 + t, y1 + t, z0)),
        "Ceiling": ((x0 - t, y0 - t, z1), (x1 + t, y1 + t, z1 + t)),
        "WallWest": ((x0 - t, y0 - t, z0), (x0, y1 + t, z1)),
        "WallEast": ((x1, y0 - t, z0), (x1 + t, y1 + t, z1)),
        "WallSouth": ((x0, y0 - t, z0), (x1, y0, z1)),
        "WallNorth": ((x0, y1, z0), (x1, y1 + t, z1)),
    }
    out = {}
    for name, (lo, hi) in slabs.items():
        n = [max(1, int(math.ceil((hi[k] - lo[k]) / cell - 1e-9))) for k in range(3)]
        m = grid_box_mesh(lo, hi, n)
        check_closed(m, name)
        out[name] = m
    return out


def _add_group(stage, group: str, parts: dict[str, tuple[MeshData, tuple[float, float, float]]]) -> int:
    """Closed meshes under ``/World/<group>``, each with its own material; their triangles."""
    stage.DefinePrim("/World/" + group, "Xform")
    tris = 0
    for name, (m, color) in parts.items():
        check_closed(m, "%s/%s" % (group, name))
        mat = add_material(stage, "/World/Looks/%sMat" % name, color)
        add_mesh(stage, "/World/%s/%s" % (group, name), m, False, mat)
        tris += triangle_count(m[1])
    return tris


def _legs(x0: float, y0: float, x1: float, y1: float, h: float, s: float) -> list[MeshData]:
    """Four square legs of side ``s`` and height ``h`` at the corners of ``x0..x1, y0..y1``."""
    return [box_mesh((x, y, 0.0), (x + s, y + s, h)) for x in (x0, x1 - s) for y in (y0, y1 - s)]


def room_furniture() -> dict[str, tuple[MeshData, tuple[float, float, float]]]:
    """The room's casters: name -> (closed mesh, colour)."""
    X, Y, Z = ROOM
    parts: dict[str, tuple[MeshData, tuple[float, float, float]]] = {}
    # table: 1.4 x 0.8 top at 0.75 .. 0.79 on four 0.06 legs, off the lamp's plumb line
    tx0, ty0, tx1, ty1 = 1.4, 1.3, 2.8, 2.1
    parts["Table"] = (merge_meshes([box_mesh((tx0, ty0, 0.75), (tx1, ty1, 0.79))] + _legs(tx0 + 0.05, ty0 + 0.05, tx1 - 0.05, ty1 - 0.05, 0.75, 0.06)),
                      (0.55, 0.38, 0.24))
    # a bowl on the table: a sphere of radius 0.1 resting on the top
    parts["Bowl"] = (translate_mesh(z_sphere(0.1, 24, 12), (1.85, 1.6, 0.79 + 0.1)), (0.8, 0.75, 0.65))
    # chair facing the table (-X): 0.45 seat at 0.45, backrest on its +X side up to 0.95
    cx0, cy0, cx1, cy1 = 3.0, 1.45, 3.45, 1.9
    parts["Chair"] = (merge_meshes([box_mesh((cx0, cy0, 0.43), (cx1, cy1, 0.47)), box_mesh((cx1 - 0.04, cy0, 0.47), (cx1, cy1, 0.95))]
                                   + _legs(cx0, cy0, cx1, cy1, 0.43, 0.04)), (0.3, 0.45, 0.6))
    # open shelf (no back panel) against the north wall: sides, five boards, a few books
    sx0, sx1, sy0, sy1, sh = 0.5, 1.7, Y - 0.35, Y - 0.01, 1.9
    shelf = [box_mesh((sx0, sy0, 0.0), (sx0 + 0.03, sy1, sh)), box_mesh((sx1 - 0.03, sy0, 0.0), (sx1, sy1, sh))]
    boards = [0.05, 0.5, 0.95, 1.4, sh - 0.03]
    shelf += [box_mesh((sx0 + 0.03, sy0, z), (sx1 - 0.03, sy1, z + 0.03)) for z in boards]
    parts["Shelf"] = (merge_meshes(shelf), (0.62, 0.5, 0.36))
    books = []
    for k, (x, w, h) in enumerate([(0.6, 0.06, 0.28), (0.67, 0.05, 0.3), (0.74, 0.07, 0.25), (1.3, 0.3, 0.08), (0.9, 0.05, 0.33),
                                   (0.96, 0.06, 0.3), (1.1, 0.06, 0.26), (1.52, 0.05, 0.3)]):
        z = boards[1 + (k % 3)] + 0.03
        books.append(box_mesh((x, sy0 + 0.05, z), (x + w, sy1 - 0.04, z + h)))
    parts["Books"] = (merge_meshes(books), (0.55, 0.2, 0.2))
    # closed window on the east wall: a frame of 0.07 bars standing 0.05 off the wall, a mullion,
    # a transom and a sill 0.2 deep below it
    wy0, wy1, wz0, wz1, b, d = 1.3, 2.9, 0.9, 2.2, 0.07, 0.05
    bars = [box_mesh((X - d, wy0, wz0), (X, wy1, wz0 + b)), box_mesh((X - d, wy0, wz1 - b), (X, wy1, wz1)),
            box_mesh((X - d, wy0, wz0 + b), (X, wy0 + b, wz1 - b)), box_mesh((X - d, wy1 - b, wz0 + b), (X, wy1, wz1 - b)),
            box_mesh((X - d, 0.5 * (wy0 + wy1) - 0.5 * b, wz0 + b), (X, 0.5 * (wy0 + wy1) + 0.5 * b, wz1 - b)),
            box_mesh((X - d, wy0 + b, 1.7 - 0.5 * b), (X, 0.5 * (wy0 + wy1) - 0.5 * b, 1.7 + 0.5 * b)),
            box_mesh((X - d, 0.5 * (wy0 + wy1) + 0.5 * b, 1.7 - 0.5 * b), (X, wy1 - b, 1.7 + 0.5 * b)),
            box_mesh((X - 0.2, wy0 - 0.1, wz0 - 0.05), (X, wy1 + 0.1, wz0))]
    parts["Window"] = (merge_meshes(bars), (0.9, 0.9, 0.88))
    # two ceiling beams across the room (along Y), shadowing the ceiling beyond them
    parts["Beams"] = (merge_meshes([box_mesh((x - 0.1, 0.0, Z - 0.22), (x + 0.1, Y, Z)) for x in (1.0, 4.1)]), (0.45, 0.33, 0.22))
    # the lamp's cord from the ceiling to 0.05 above the sphere, and a canopy on the ceiling
    lx, ly, lz = ROOM_LAMP
    parts["Cord"] = (merge_meshes([bar_mesh((lx, ly, lz + ROOM_LAMP_RADIUS + 0.05), (lx, ly, Z), 0.012),
                                   box_mesh((lx - 0.06, ly - 0.06, Z - 0.03), (lx + 0.06, ly + 0.06, Z))]), (0.15, 0.15, 0.15))
    return parts


def scene_room_lamp(out_dir: str) -> dict[str, object]:
    """A sphere light hanging in a furnished closed room: ``room_lamp.usda``."""
    path = os.path.join(out_dir, "room_lamp.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    X, Y, Z = ROOM
    colors = {"Floor": (0.7, 0.62, 0.5), "Ceiling": (0.9, 0.9, 0.88)}
    tris = _add_group(stage, "Room", {n: (m, colors.get(n, (0.82, 0.8, 0.74))) for n, m in shell((0, 0, 0), ROOM).items()})
    tris += _add_group(stage, "Furniture", room_furniture())
    add_sphere_light(stage, "/World/Lamp", ROOM_LAMP, ROOM_LAMP_RADIUS, intensity=90.0)
    set_doc_string(world, "wsoft:doc", (
        "A sphere light hanging in a furnished closed room. Inside, the room spans x in [0, %g], y in "
        "[0, %g], z in [0, %g]; /World/Room holds its floor, ceiling and four walls as closed slabs "
        "%g thick that touch without gaps (their faces grids of %g), so no light leaves it. "
        "/World/Lamp is a SphereLight of radius %g at (%g, %g, %g), hanging on a cord (/World/"
        "Furniture/Cord) that stops 0.05 above it. Casters (/World/Furniture, each closed): a "
        "table (1.4 x 0.8 top at 0.75-0.79) with a bowl (sphere r 0.1), a chair with a backrest, "
        "an open shelf with books against the north wall (y = %g), a closed window's frame, "
        "mullion, transom and sill standing 0.05 off the east wall (x = %g), and two ceiling beams "
        "across the room at x = 1 and 4.1. Receivers surround the light: floor below, ceiling "
        "above, walls on every side. The camera in the corner (%g, %g, %g) looks at the "
        "opposite one and sees the floor, the north and east walls, the ceiling and the lamp."
        % ((X, Y, Z, SHELL_THICK, SHELL_CELL, ROOM_LAMP_RADIUS) + ROOM_LAMP + (Y, X) + ROOM_CAMERA[0])))
    add_scene_camera(stage, ROOM_CAMERA[0], ROOM_CAMERA[1], (0.0, 0.0, 1.0), focal=ROOM_FOCAL, clip=(0.05, 50.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def corridor_casters() -> dict[str, tuple[MeshData, tuple[float, float, float]]]:
    """The corridor's casters: name -> (closed mesh, colour)."""
    L, Wd, Z = CORRIDOR
    s, yc = CORRIDOR_PILLAR
    h = 0.5 * s
    pillars = [box_mesh((x - h, sy * yc - h, 0.0), (x + h, sy * yc + h, Z)) for x in CORRIDOR_PILLARS for sy in (-1, 1)]
    # a beam across the ceiling over each pair of pillars
    beams = [box_mesh((x - h, -0.5 * Wd, Z - 0.3), (x + h, 0.5 * Wd, Z)) for x in CORRIDOR_PILLARS]
    # crates on the floor: one between the camera and the torch, two far ahead
    crates = [box_mesh((3.7, -0.1, 0.0), (4.3, 0.5, 0.6)), box_mesh((13.5, -0.8, 0.0), (14.2, -0.1, 0.7)),
              box_mesh((18.2, 0.2, 0.0), (18.7, 0.7, 0.5))]
    return {"Pillars": (merge_meshes(pillars), (0.6, 0.58, 0.55)), "Beams": (merge_meshes(beams), (0.45, 0.33, 0.22)),
            "Crates": (merge_meshes(crates), (0.6, 0.45, 0.25))}


def scene_corridor_torch(out_dir: str) -> dict[str, object]:
    """A small sphere light in a long closed corridor with pillars: ``corridor_torch.usda``."""
    path = os.path.join(out_dir, "corridor_torch.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    L, Wd, Z = CORRIDOR
    colors = {"Floor": (0.55, 0.52, 0.48), "Ceiling": (0.7, 0.68, 0.64)}
    lo, hi = (0.0, -0.5 * Wd, 0.0), (L, 0.5 * Wd, Z)
    tris = _add_group(stage, "Corridor", {n: (m, colors.get(n, (0.72, 0.68, 0.6))) for n, m in shell(lo, hi).items()})
    tris += _add_group(stage, "Casters", corridor_casters())
    add_sphere_light(stage, "/World/Torch", CORRIDOR_TORCH, CORRIDOR_TORCH_RADIUS, intensity=3000.0)
    s, yc = CORRIDOR_PILLAR
    set_doc_string(world, "wsoft:doc", (
        "A small sphere light (a torch) in a long closed corridor. Inside, the corridor spans x in "
        "[0, %g], y in [%g, %g], z in [0, %g]; /World/Corridor holds its floor, ceiling, two side "
        "walls and two end walls as closed slabs %g thick that touch without gaps (faces grids of "
        "%g). /World/Casters: %d pairs of %g x %g pillars from floor to ceiling at x = %s, centred "
        "at y = +-%g (a gap to the wall behind each), a %g-wide beam across the ceiling over each "
        "pair, and three crates on the floor (one between the camera and the torch, two far "
        "ahead). /World/Torch is a SphereLight of radius %g at (%g, %g, %g). The camera at (%g, "
        "%g, %g) looks down +X: receivers lie far ahead of the torch, beside it, above it and "
        "behind it (between the camera and the torch), and the torch is in view."
        % ((L, -0.5 * Wd, 0.5 * Wd, Z, SHELL_THICK, SHELL_CELL, len(CORRIDOR_PILLARS), s, s,
            ", ".join("%g" % x for x in CORRIDOR_PILLARS), yc, s, CORRIDOR_TORCH_RADIUS) + CORRIDOR_TORCH + CORRIDOR_CAMERA[0])))
    add_scene_camera(stage, CORRIDOR_CAMERA[0], CORRIDOR_CAMERA[1], (0.0, 0.0, 1.0), focal=CORRIDOR_FOCAL, clip=(0.05, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}

