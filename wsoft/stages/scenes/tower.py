"""``tower``: a lattice tower of thin bars under a point light, for irregular z-buffer shadows
(Galoppo, "Eye-View Pixel Anti-Aliasing for Irregular Shadow Mapping", Fig. 1.6.4):
high-frequency hard shadows of geometry thinner than a pixel."""

from __future__ import annotations

import os

import numpy as np

from wsoft.stages.builders import add_material, add_mesh, add_point_light, make_stage, set_doc_string
from wsoft.stages.mesh import MeshData, bar_mesh, check_closed, merge_meshes, quad_mesh, triangle_count
from wsoft.stages.scenes import add_scene_camera


TOWER_HEIGHT = 4.0
TOWER_BASE_HALF = 0.8  # the legs stand on a 1.6 x 1.6 square
TOWER_TOP_HALF = 0.25  # and meet the top ring on a 0.5 x 0.5 square
TOWER_LEVELS = 10  # a ring every 0.4
TOWER_APEX = 4.5  # the spire's tip
TOWER_LEG_THICK = 0.035
TOWER_RING_THICK = 0.025
TOWER_BRACE_THICK = 0.02
# crossarms: (ring level of the arm's bottom chords, |x| of the tip); the top chord starts
# on the next ring up
TOWER_ARMS = [(7, 1.5), (9, 1.2)]
TOWER_ARM_CELLS = 4
TOWER_LIGHT = (2.5, -2.0, 7.0)
TOWER_GROUND_HALF = 8.0


def tower_corner(k: int, z: float) -> np.ndarray:
    """Point of leg k (counter-clockwise from (-, -)) at height z."""
    sx, sy = [(-1, -1), (1, -1), (1, 1), (-1, 1)][k % 4]
    h = TOWER_BASE_HALF + (TOWER_TOP_HALF - TOWER_BASE_HALF) * z / TOWER_HEIGHT
    return np.array([sx * h, sy * h, z])


def tower_parts() -> dict[str, list[MeshData]]:
    """Bars of the lattice tower by group: Legs, Rings, Braces, Arms."""
    dz = TOWER_HEIGHT / TOWER_LEVELS
    zs = [dz * i for i in range(TOWER_LEVELS + 1)]
    legs: list[MeshData] = []
    rings: list[MeshData] = []
    braces: list[MeshData] = []
    arms: list[MeshData] = []
    for k in range(4):
        for i in range(TOWER_LEVELS):  # one leg member per panel
            legs.append(bar_mesh(tower_corner(k, zs[i]), tower_corner(k, zs[i + 1]),
                                 TOWER_LEG_THICK))
        legs.append(bar_mesh(tower_corner(k, TOWER_HEIGHT), (0.0, 0.0, TOWER_APEX),
                             TOWER_LEG_THICK))  # spire
    for i in range(1, TOWER_LEVELS + 1):
        for k in range(4):  # horizontal ring
            rings.append(bar_mesh(tower_corner(k, zs[i]), tower_corner(k + 1, zs[i]),
                                  TOWER_RING_THICK))
        for k in range(2):  # plan bracing across the ring
            rings.append(bar_mesh(tower_corner(k, zs[i]), tower_corner(k + 2, zs[i]),
                                  TOWER_BRACE_THICK))
    for i in range(TOWER_LEVELS):
        zm = 0.5 * (zs[i] + zs[i + 1])
        for k in range(4):
            # X-bracing of the face (k, k + 1) between two rings, and a secondary
            # horizontal through the middle of the panel
            braces.append(bar_mesh(tower_corner(k, zs[i]), tower_corner(k + 1, zs[i + 1]),
                                   TOWER_BRACE_THICK))
            braces.append(bar_mesh(tower_corner(k + 1, zs[i]), tower_corner(k, zs[i + 1]),
                                   TOWER_BRACE_THICK))
            rings.append(bar_mesh(tower_corner(k, zm), tower_corner(k + 1, zm),
                                  TOWER_BRACE_THICK))
    n = TOWER_ARM_CELLS
    for level, reach in TOWER_ARMS:
        z0, z1 = zs[level], zs[level + 1]
        for side in (1, -1):  # +X arm from the face of legs 1, 2; -X from legs 3, 0
            b1 = tower_corner(1 if side > 0 else 3, z0)
            b2 = tower_corner(2 if side > 0 else 0, z0)
            top = np.array([side * tower_corner(1, z1)[0], 0.0, z1])
            tip = np.array([side * reach, 0.0, z0])

            def at(p: np.ndarray, j: int) -> np.ndarray:
                return p + (tip - p) * (j / n)

            for p in (b1, b2, top):  # three chords
                arms.append(bar_mesh(p, tip, TOWER_RING_THICK))
            for j in range(1, n):  # web: cross bar and two diagonals to the top chord
                arms.append(bar_mesh(at(b1, j), at(b2, j), TOWER_BRACE_THICK))
                arms.append(bar_mesh(at(b1, j), at(top, j), TOWER_BRACE_THICK))
                arms.append(bar_mesh(at(b2, j), at(top, j), TOWER_BRACE_THICK))
            for j in range(n - 1):  # zig-zag in the bottom plane
                arms.append(bar_mesh(at(b1, j), at(b2, j + 1), TOWER_BRACE_THICK))
    return {"Legs": legs, "Rings": rings, "Braces": braces, "Arms": arms}


def scene_tower(out_dir: str) -> dict[str, object]:
    """The lattice tower over a single-sided ground under a point light: ``tower.usda``."""
    path = os.path.join(out_dir, "tower.usda")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    g = TOWER_GROUND_HALF
    ground = quad_mesh([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)])
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.78)))
    tris = triangle_count(ground[1])

    steel = add_material(stage, "/World/Looks/SteelMat", (0.45, 0.47, 0.5), roughness=0.5)
    stage.DefinePrim("/World/Tower", "Xform")
    counts = {}
    for name, bars in tower_parts().items():
        m = merge_meshes(bars)  # bars overlap at the joints; each is closed on its own
        check_closed(m, "Tower/" + name)
        add_mesh(stage, "/World/Tower/" + name, m, False, steel)
        counts[name] = len(bars)
        tris += triangle_count(m[1])

    add_point_light(stage, "/World/Light", TOWER_LIGHT, intensity=60.0, radius=0.0)
    set_doc_string(world, "wsoft:doc", (
        "Lattice tower for irregular z-buffer (Galoppo, 'Eye-View Pixel Anti-Aliasing for "
        "Irregular Shadow Mapping', fig. 1.6.4): high-frequency hard shadows of thin bars on "
        "the ground. Four slightly inclined legs rise from a 1.6 x 1.6 square at z = 0 to a "
        "0.5 x 0.5 square at z = 4, with a spire to (0, 0, 4.5). Rings every 0.4 with plan "
        "bracing, X-braces and a middle horizontal on every face panel, and two levels of "
        "truss crossarms (z = 2.8 to |x| = 1.5, z = 3.6 to |x| = 1.2). Every bar is a closed "
        "box of square cross-section (legs 0.035, rings and chords 0.025, braces 0.02), merged "
        "per group into /World/Tower/{Legs, Rings, Braces, Arms} (%d, %d, %d, %d bars). The "
        "light /World/Light is a point light (SphereLight, radius 0, treatAsPoint) at "
        "(%g, %g, %g); the shadow falls on the single-sided 16 x 16 ground toward -x, +y."
        % ((counts["Legs"], counts["Rings"], counts["Braces"], counts["Arms"]) + TOWER_LIGHT)))

    # raised 3/4 view from the side of the shadow, which runs from the base toward (-5, 3.5)
    add_scene_camera(stage, (-7.5, -1.5, 6.5), (-1.5, 1.5, 0.9), (0.0, 0.0, 1.0), clip=(0.1, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
