"""Analogs of the test scenes of Forest, Barthe, Guennebaud and Paulin 2009 (soft textured shadow
volumes): perforated (alpha-tested) triangles beside opaque meshes, for ``pwedge``, ``dcs`` and
their STSV part.

* ``fence_perforated`` / ``fence_mesh`` (Fig. 11): one wire fence as 2 perforated triangles, and
  the same fence with its wires modelled as flat opaque strips in the fence's plane where the texture
  is opaque (223,584 triangles, the order of the paper's 233,358): the same silhouette from the light.
* ``hl2_like`` (Fig. 7a): ~4k perforated triangles (foliage cards, fences) outdoors, opaque
  buildings, 2 distant lights.
* ``factory`` (Fig. 7b): high-poly opaque machinery, 14 perforated triangles (grates), 4 sphere
  lights close to the geometry.
* ``greece`` (Fig. 7c): ~26k leaf triangles (two per leaf card), columns and ground, 3 lights.
* ``wedge_overlap`` (Fig. 4a): penumbra wedges' overlap artifact: two opaque sheets whose
  silhouettes overlap as seen from the ground, and a perforated fence card over an opaque sheet's
  penumbra, under one rect light.
"""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.stages.builders import (
    add_cutout_material,
    add_material,
    add_mesh,
    add_rect_light,
    add_sphere_light,
    add_sun,
    make_stage,
    set_doc_string,
)
from wsoft.stages.mesh import (
    MeshData,
    box_mesh,
    grid_box_mesh,
    grid_quad_mesh,
    merge_meshes,
    prism_z,
    torus_z,
    translate_mesh,
    triangle_count,
    z_sphere,
)
from wsoft.stages.scenes import add_scene_camera
from wsoft.stages.textures import write_alpha_png

# --------------------------------------------------------------------------- textures and helpers

FENCE_TILE = 16  # texels per fence cell; the wires are the 2 texels around each cell border
FENCE_CELLS = (128, 72)  # cells along the fence and up it
FENCE_SIZE = (4.0, 2.25)  # metres: 3.125 cm cells
FENCE_BASE = 0.1  # bottom edge height


def fence_tile() -> np.ndarray:
    """The fence texture's tile: the wires (1 texel each side of a cell border) are True."""
    t = np.arange(FENCE_TILE)
    wire = (t < 1) | (t >= FENCE_TILE - 1)
    return wire[:, None] | wire[None, :]


def leaf_alpha(size: int = 64) -> np.ndarray:
    """A leaf: a pointed ellipse along the image's vertical axis with a few notches."""
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5) / size
    x, y = (xx - 0.5) * 2.0, (yy - 0.5) * 2.0
    width = 0.75 * np.sqrt(np.clip(1.0 - y * y, 0, 1)) * (1.0 - 0.25 * (y > 0.5))
    notch = 0.08 * np.sin(9 * math.pi * y)
    return np.abs(x) < width + notch - 0.05


def foliage_alpha(size: int = 64, seed: int = 4) -> np.ndarray:
    """A cluster of small leaves on a card: random discs."""
    rng = np.random.default_rng(seed)
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5) / size
    m = np.zeros((size, size), bool)
    for c, r in zip(rng.uniform(0.12, 0.88, (30, 2)), rng.uniform(0.04, 0.1, 30)):
        m |= (xx - c[0]) ** 2 + (yy - c[1]) ** 2 < r * r
    return m


def grate_alpha(size: int = 32) -> np.ndarray:
    """The grate texture: bars 3 texels wide every 8, both ways."""
    t = np.arange(size)
    bar = (t % 8) < 3
    return bar[:, None] | bar[None, :]


def cards(stage, path: str, corners: np.ndarray, uv_max, material) -> int:
    """Double-sided quads (``corners`` [Q, 4, 3], counter-clockwise) with face-varying ``st``
    from (0, 0) to ``uv_max`` (each quad split into 2 perforated triangles on load)."""
    q = len(corners)
    m = (corners.reshape(-1, 3), [4] * q, list(range(4 * q)))
    u, v = uv_max
    st = np.tile(np.array([(0, 0), (u, 0), (u, v), (0, v)], np.float32), (q, 1))
    add_mesh(stage, path, m, True, material, st=st)
    return 2 * q


def ground(stage, half: float, n: int = 1, color=(0.7, 0.68, 0.62)) -> int:
    """A single-sided ``/World/Ground`` of half-side ``half`` at z = 0 as ``n`` x ``n`` quads; its triangles."""
    g = grid_quad_mesh((-half, -half, 0.0), (2 * half, 0, 0), (0, 2 * half, 0), n, n)
    add_mesh(stage, "/World/Ground", g, False, add_material(stage, "/World/Looks/GroundMat", color))
    return triangle_count(g[1])


def quad_at(c, u, v) -> np.ndarray:
    """The 4 corners of a quad centred at ``c`` with half-axes ``u`` and ``v`` (CCW about u x v)."""
    c, u, v = (np.asarray(a, float) for a in (c, u, v))
    return np.stack([c - u - v, c + u - v, c + u + v, c - u + v])


# --------------------------------------------------------------------------- fences


def fence_quad() -> np.ndarray:
    """The fence's one quad in the plane y = 0, as ``[1, 4, 3]`` corners."""
    w, h = FENCE_SIZE
    return np.array([[(-w / 2, 0.0, FENCE_BASE), (w / 2, 0.0, FENCE_BASE), (w / 2, 0.0, FENCE_BASE + h), (-w / 2, 0.0, FENCE_BASE + h)]])


def fence_common(stage, out_dir: str) -> int:
    """The ground, light and camera both fence stages share; the ground's triangles."""
    tris = ground(stage, 4.0)
    add_sphere_light(stage, "/World/Light", (0.6, 2.2, 3.2), 0.35, 40.0)
    add_scene_camera(stage, (1.2, -4.5, 2.6), (0.0, 1.0, 0.6), (0, 0, 1), clip=(0.1, 100.0))
    return tris


def scene_fence_perforated(out_dir: str) -> dict[str, object]:
    """Fig. 11a analog: the wire fence as 2 perforated triangles: ``fence_perforated.usda``."""
    path = os.path.join(out_dir, "fence_perforated.usda")
    write_alpha_png(os.path.join(out_dir, "textures", "fence_alpha.png"), fence_tile())
    stage = make_stage("Z", path)
    tris = fence_common(stage, out_dir)
    mat = add_cutout_material(stage, "/World/Looks/FenceMat", (0.5, 0.5, 0.52), "textures/fence_alpha.png")
    tris += cards(stage, "/World/Fence", fence_quad(), FENCE_CELLS, mat)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 11a analog: a %g x %g m wire fence in the plane y = 0 (bottom at z = %g) as "
        "2 double-sided perforated triangles; textures/fence_alpha.png (a %d x %d tile: wires are the 2 texels "
        "around its border) repeated %d x %d times, opacityThreshold 0.5. Ground 8 x 8; a sphere light "
        "(radius 0.35) behind the fence. fence_mesh.usdc is the same fence as opaque geometry."
        % (FENCE_SIZE + (FENCE_BASE, FENCE_TILE, FENCE_TILE) + FENCE_CELLS)))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


FENCE_SEGMENTS = 6  # quads along each wire strip of fence_mesh


def fence_wires(segments: int = FENCE_SEGMENTS) -> MeshData:
    """The fence texture's opaque pattern as geometry in the texture's own plane y = 0: a flat
    strip (the wire's width, 2 texels of the tile) along every cell side, the horizontal ones
    holding the crossings, no two overlapping, so that from any point the strips hide what the
    texture's opaque texels hide (and a technique adding silhouettes' coverages counts each once). Each strip is ``segments`` quads along its length (the mesh's triangle count, as the
    paper's mesh fence, is what a triangle-based technique pays for)."""
    w, h = FENCE_SIZE
    nu, nv = FENCE_CELLS
    cell = w / nu
    t = 2.0 * cell / FENCE_TILE  # the wire: 2 texels of the tile
    xs = -w / 2 + cell * np.arange(nu + 1)
    zs = FENCE_BASE + cell * np.arange(nv + 1)
    strips = []  # (x0, z0, x1, z1, along x)
    for i in range(nu + 1):  # vertical wires, one strip per cell, between the horizontal ones
        x0, x1 = max(xs[i] - t / 2, -w / 2), min(xs[i] + t / 2, w / 2)
        for j in range(nv):
            strips.append((x0, zs[j] + t / 2, x1, zs[j + 1] - t / 2, False))
    for j in range(nv + 1):  # horizontal wires, one strip per cell holding its -x crossing (the last both)
        z0, z1 = max(zs[j] - t / 2, FENCE_BASE), min(zs[j] + t / 2, FENCE_BASE + h)
        for i in range(nu):
            strips.append((xs[i] - t / 2 if i else xs[i], z0, xs[i + 1] - t / 2 if i < nu - 1 else xs[i + 1], z1, True))
    a = np.asarray([r[:4] for r in strips], float)
    along_x = np.asarray([r[4] for r in strips])
    f = np.linspace(0.0, 1.0, segments + 1)
    # per strip, segments + 1 cross-sections of 2 points each: (long, short) -> (x, z)
    lo_l = np.where(along_x, a[:, 0], a[:, 1])
    hi_l = np.where(along_x, a[:, 2], a[:, 3])
    lo_s = np.where(along_x, a[:, 1], a[:, 0])
    hi_s = np.where(along_x, a[:, 3], a[:, 2])
    lng = lo_l[:, None] + (hi_l - lo_l)[:, None] * f[None, :]  # [S, segments + 1]
    pts = np.zeros((len(a), segments + 1, 2, 3))
    for k, sh in enumerate((lo_s, hi_s)):
        pts[:, :, k, 0] = np.where(along_x[:, None], lng, sh[:, None])
        pts[:, :, k, 2] = np.where(along_x[:, None], sh[:, None], lng)
    base = (np.arange(len(a)) * 2 * (segments + 1))[:, None] + 2 * np.arange(segments)[None, :]  # [S, segments]
    quads = np.stack([base, base + 2, base + 3, base + 1], -1)
    return pts.reshape(-1, 3), [4] * quads.shape[0] * segments, quads.reshape(-1).tolist()


def scene_fence_mesh(out_dir: str) -> dict[str, object]:
    """Fig. 11b analog: the same fence with its wires as flat opaque strips: ``fence_mesh.usdc``."""
    path = os.path.join(out_dir, "fence_mesh.usdc")
    stage = make_stage("Z", path)
    tris = fence_common(stage, out_dir)
    wires = fence_wires()
    add_mesh(stage, "/World/Fence", wires, True, add_material(stage, "/World/Looks/FenceMat", (0.5, 0.5, 0.52)))
    tris += triangle_count(wires[1])
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 11b analog: fence_perforated's fence with its wires modelled as %d flat "
        "double-sided strips in the fence's plane where the texture is opaque (each %d quads along its length; %d "
        "opaque triangles): the same silhouette from the light as the perforated texture; same ground, light and camera."
        % (len(wires[1]) // FENCE_SEGMENTS, FENCE_SEGMENTS, triangle_count(wires[1]))))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# --------------------------------------------------------------------------- hl2_like


def foliage_tree(rng, base, n_cards: int, height: float, radius: float) -> np.ndarray:
    """``n_cards`` foliage cards scattered in a crown (random orientation)."""
    out = []
    for _ in range(n_cards):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        c = np.asarray(base) + (0, 0, height) + d * radius * rng.uniform(0.3, 1.0) * (1, 1, 0.8)
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        b = np.cross(a, rng.normal(size=3))
        b /= np.linalg.norm(b)
        s = rng.uniform(0.35, 0.6)
        out.append(quad_at(c, a * s, np.cross(b, a) * s))
    return np.array(out)


def scene_hl2_like(out_dir: str) -> dict[str, object]:
    """Fig. 7a analog: foliage cards, a ring fence and buildings under 2 distant lights: ``hl2_like.usdc``."""
    path = os.path.join(out_dir, "hl2_like.usdc")
    write_alpha_png(os.path.join(out_dir, "textures", "fence_alpha.png"), fence_tile())
    write_alpha_png(os.path.join(out_dir, "textures", "foliage_alpha.png"), foliage_alpha(), (60, 120, 50))
    stage = make_stage("Z", path)
    rng = np.random.default_rng(2009)
    tris = ground(stage, 30.0, 100)
    bmat = add_material(stage, "/World/Looks/BuildingMat", (0.65, 0.6, 0.55))
    stage.DefinePrim("/World/Buildings", "Xform")
    for k, (x, y, sx, sy, sz) in enumerate([(-14, 8, 6, 5, 8), (-4, 14, 8, 5, 10), (9, 12, 5, 6, 7), (15, -2, 5, 7, 9),
                                            (-16, -10, 6, 6, 6), (4, -16, 7, 5, 8), (-6, -2, 3, 3, 4), (12, -14, 4, 4, 5)]):
        b = grid_box_mesh((x - sx / 2, y - sy / 2, 0.0), (x + sx / 2, y + sy / 2, float(sz)), (16, 16, 24))
        add_mesh(stage, f"/World/Buildings/B{k}", b, False, bmat)
        tris += triangle_count(b[1])
    fol = add_cutout_material(stage, "/World/Looks/FoliageMat", (0.25, 0.5, 0.2), "textures/foliage_alpha.png")
    stage.DefinePrim("/World/Trees", "Xform")
    trunk_mat = add_material(stage, "/World/Looks/TrunkMat", (0.4, 0.3, 0.2))
    perforated = 0
    positions = [(x, y) for x in (-20, -10, 0, 10, 20) for y in (-20, -8, 4, 20)] + [(-24, 0), (24, 6), (-2, 24), (6, -24), (0, 0), (8, 2)]
    for k, (x, y) in enumerate(positions[:25]):
        x, y = x + rng.uniform(-2, 2), y + rng.uniform(-2, 2)
        h = rng.uniform(3.0, 5.0)
        trunk = prism_z(8, 0.15, 0.0, h, center=(x, y))
        add_mesh(stage, f"/World/Trees/T{k:02d}/Trunk", trunk, False, trunk_mat)
        tris += triangle_count(trunk[1])
        c = cards(stage, f"/World/Trees/T{k:02d}/Foliage", foliage_tree(rng, (x, y, 0), 76, h, 1.8), (1, 1), fol)
        perforated += c
        tris += c
    fmat = add_cutout_material(stage, "/World/Looks/FenceMat", (0.5, 0.5, 0.52), "textures/fence_alpha.png")
    segs = []
    n_fence = (4002 - perforated) // 2  # fence panels 2 m wide, 1.5 m tall, along a broken line
    for i in range(n_fence):
        a = 2.0 * math.pi * i / n_fence
        r = 27.0 + 0.5 * math.sin(5 * a)
        c = (r * math.cos(a), r * math.sin(a), 0.8)
        tdir = np.array([-math.sin(a), math.cos(a), 0.0])
        segs.append(quad_at(c, tdir * (math.pi * r / n_fence), (0, 0, 0.75)))
    c = cards(stage, "/World/Fence", np.array(segs), (32, 24), fmat)
    perforated += c
    tris += c
    add_sun(stage, "/World/Sun", 1.0, intensity=3.0, toward=(0.5, -0.35, 0.8))
    add_sun(stage, "/World/Sky", 4.0, intensity=1.0, toward=(-0.6, 0.5, 0.6))
    add_scene_camera(stage, (-22.0, -22.0, 9.0), (0.0, 0.0, 1.5), (0, 0, 1), focal=20.0, clip=(0.1, 300.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 7a (HL2) analog: %d perforated triangles outdoors — 25 trees of 76 "
        "double-sided foliage cards (textures/foliage_alpha.png) on opaque trunks, and a ring fence of "
        "double-sided panels (textures/fence_alpha.png) — among 8 opaque gridded buildings on a 60 x 60 gridded "
        "ground; 2 distant lights (sun angle 1 deg, sky 4 deg). %d triangles." % (perforated, tris)))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "perforated": perforated}


# --------------------------------------------------------------------------- factory


def scene_factory(out_dir: str) -> dict[str, object]:
    """Fig. 7b analog: high-poly machinery and perforated grates under 4 sphere lights: ``factory.usdc``."""
    path = os.path.join(out_dir, "factory.usdc")
    write_alpha_png(os.path.join(out_dir, "textures", "grate_alpha.png"), grate_alpha())
    stage = make_stage("Z", path)
    tris = ground(stage, 10.0, 20)
    metal = add_material(stage, "/World/Looks/MetalMat", (0.55, 0.57, 0.6), roughness=0.4)
    paint = add_material(stage, "/World/Looks/PaintMat", (0.7, 0.45, 0.15))
    stage.DefinePrim("/World/Machines", "Xform")
    parts = []
    for k in range(6):  # tanks: high-poly cylinders with toroidal rings
        x, y = -6.0 + 2.4 * k, 3.0 * (-1) ** k
        parts.append(prism_z(256, 0.8, 0.0, 3.0, center=(x, y)))
        for z in (0.6, 1.5, 2.4):
            parts.append(translate_mesh(torus_z(0.85, 0.07, 160, 24), (x, y, z)))
        parts.append(translate_mesh(z_sphere(0.8, 96, 48), (x, y, 3.0)))
    m = merge_meshes(parts)
    add_mesh(stage, "/World/Machines/Tanks", m, False, metal)
    tris += triangle_count(m[1])
    pipes = []
    for k in range(5):  # horizontal pipes along x (prisms turned: (x, y, z) -> (z, x, y))
        p = prism_z(96, 0.12, -8.0, 8.0)
        p = (p[0][:, [2, 0, 1]] + (0.0, -1.0 + 0.5 * k, 4.0 + 0.3 * (k % 2)), p[1], p[2])
        pipes.append(p)
    m = merge_meshes(pipes)
    add_mesh(stage, "/World/Machines/Pipes", m, False, paint)
    tris += triangle_count(m[1])
    g = add_cutout_material(stage, "/World/Looks/GrateMat", (0.3, 0.3, 0.32), "textures/grate_alpha.png")
    grates = [quad_at((-6.0 + 2.4 * k, 0.0, 2.0), (1.0, 0, 0), (0, 1.4, 0)) for k in range(6)]
    grates.append(quad_at((0.0, 0.0, 5.0), (7.5, 0, 0), (0, 1.5, 0)))
    c = cards(stage, "/World/Grates", np.array(grates), (4, 6), g)
    tris += c
    for k, pos in enumerate([(-4.8, 0.0, 3.2), (2.4, 0.0, 3.4), (-1.0, 1.2, 5.8), (5.0, -1.5, 1.0)]):
        add_sphere_light(stage, f"/World/Lamp{k}", pos, 0.15, 8.0)
    add_scene_camera(stage, (3.0, -9.0, 6.0), (-1.0, 0.5, 1.5), (0, 0, 1), focal=18.0, clip=(0.1, 100.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 7b (factory) analog: high-poly opaque machinery (6 tanks of 256-sided "
        "cylinders, domes and toroidal rings; 5 pipes), 14 perforated triangles (7 double-sided grates, "
        "textures/grate_alpha.png): 6 walkways between the tanks at z = 2 and one long catwalk at z = 5; "
        "4 small sphere lights (radius 0.15) close to the geometry. %d triangles." % tris))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "perforated": c}


# --------------------------------------------------------------------------- greece


def scene_greece(out_dir: str) -> dict[str, object]:
    """Fig. 7c analog: leaf cards in vines around a colonnade under 3 sphere lights: ``greece.usdc``."""
    path = os.path.join(out_dir, "greece.usdc")
    write_alpha_png(os.path.join(out_dir, "textures", "leaf_alpha.png"), leaf_alpha(), (70, 130, 40))
    stage = make_stage("Z", path)
    rng = np.random.default_rng(1896)
    tris = ground(stage, 12.0, 40, color=(0.8, 0.75, 0.62))
    marble = add_material(stage, "/World/Looks/MarbleMat", (0.9, 0.88, 0.84))
    cols = []
    for i in range(6):
        for j in (-1, 1):
            x, y = -5.0 + 2.0 * i, 2.5 * j
            cols.append(prism_z(48, 0.3, 0.3, 4.0, center=(x, y)))
            cols.append(box_mesh((x - 0.4, y - 0.4, 0.0), (x + 0.4, y + 0.4, 0.3)))
            cols.append(box_mesh((x - 0.4, y - 0.4, 4.0), (x + 0.4, y + 0.4, 4.3)))
    cols.append(grid_box_mesh((-6.0, -3.2, 4.3), (6.0, 3.2, 4.8), (48, 24, 2)))  # architrave
    m = merge_meshes(cols)
    add_mesh(stage, "/World/Temple", m, False, marble)
    tris += triangle_count(m[1])
    leaf = add_cutout_material(stage, "/World/Looks/LeafMat", (0.3, 0.55, 0.2), "textures/leaf_alpha.png", wrap="clamp")
    stage.DefinePrim("/World/Vines", "Xform")
    leaves = 0
    n_leaves = 13075  # 26,150 perforated triangles, as the paper's Greece scene
    per = [n_leaves // 5 + (1 if k < n_leaves % 5 else 0) for k in range(5)]
    for k, n in enumerate(per):  # 5 leafy vines/bushes: over the architrave and at the columns
        centre = np.array([(-4.0, 0.0, 5.2), (3.0, 0.0, 5.2), (-7.5, -4.0, 1.5), (7.5, 4.0, 1.8), (0.0, -6.0, 1.2)][k])
        radius = np.array([(2.5, 2.5, 0.8), (2.5, 2.5, 0.8), (1.6, 1.6, 1.5), (1.6, 1.6, 1.8), (2.5, 1.2, 1.2)][k])
        c = centre + rng.normal(0, 0.5, (n, 3)) * radius
        c[:, 2] = np.maximum(c[:, 2], 0.15)
        a = rng.normal(size=(n, 3))
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b = np.cross(a, rng.normal(size=(n, 3)))
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        s = rng.uniform(0.06, 0.12, (n, 1))
        u, v = b * s * 0.6, a * s
        quads = np.stack([c - u - v, c + u - v, c + u + v, c - u + v], 1)
        leaves += cards(stage, f"/World/Vines/V{k}", quads, (1, 1), leaf)
    tris += leaves
    add_sphere_light(stage, "/World/Light0", (6.0, -7.0, 9.0), 0.8, 30.0)
    add_sphere_light(stage, "/World/Light1", (-7.0, -4.0, 6.0), 0.5, 15.0)
    add_sphere_light(stage, "/World/Light2", (0.0, 6.0, 7.0), 0.6, 15.0)
    add_scene_camera(stage, (9.0, -12.0, 6.0), (0.0, 0.0, 2.0), (0, 0, 1), focal=20.0, clip=(0.1, 200.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 7c (Greece) analog: %d perforated leaf triangles (%d double-sided leaf "
        "cards of 2 triangles, textures/leaf_alpha.png, in 5 vines and bushes /World/Vines/V*) around a "
        "colonnade of 12 columns under an architrave (/World/Temple); 24 x 24 ground; 3 sphere lights. "
        "%d triangles." % (leaves, leaves // 2, tris)))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "perforated": leaves}


# --------------------------------------------------------------------------- wedge_overlap


def scene_wedge_overlap(out_dir: str) -> dict[str, object]:
    """Fig. 4(a) analog, the penumbra wedges' overlap artifact: ``wedge_overlap.usda``."""
    path = os.path.join(out_dir, "wedge_overlap.usda")
    write_alpha_png(os.path.join(out_dir, "textures", "fence_alpha.png"), fence_tile())
    stage = make_stage("Z", path)
    tris = ground(stage, 4.0)
    add_rect_light(stage, "/World/Light", (0.0, 0.0, 3.0), 1.0, 1.0, intensity=10.0)
    grey = add_material(stage, "/World/Looks/SheetMat", (0.55, 0.5, 0.45))
    sheets = {"/World/SheetA": ((-2.0, -1.0), (0.0, 1.0), 1.0), "/World/SheetB": ((-2.2, -1.0), (-0.2, 1.0), 1.5),
              "/World/SheetD": ((1.0, 1.5), (3.0, 3.0), 1.0)}
    for name, ((x0, y0), (x1, y1), z) in sheets.items():
        add_mesh(stage, name, ([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)], [4], [0, 1, 2, 3]), True, grey)
        tris += 2
    fence = add_cutout_material(stage, "/World/Looks/FenceMat", (0.5, 0.5, 0.52), "textures/fence_alpha.png")
    tris += cards(stage, "/World/FenceC", np.array([[(0.0, 1.5, 1.5), (2.0, 1.5, 1.5), (2.0, 3.0, 1.5), (0.0, 3.0, 1.5)]]), (16, 12), fence)
    add_scene_camera(stage, (0.4, -4.5, 5.0), (0.2, 0.9, 0.0), (0, 0, 1), clip=(0.1, 100.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "Forest et al. 2009 Fig. 4(a) analog, the penumbra wedges' overlap artifact: a 1 x 1 rect light at z = 3 over an "
        "8 x 8 ground. Opaque double-sided sheets SheetA (x -2..0, y -1..1, z = 1) and SheetB (x -2.2..-0.2, y -1..1, "
        "z = 1.5), whose right edges both cut the light seen from the ground near x = 0 (wedges add the two covered "
        "areas: over-shadowed where the light's centre is visible, under-shadowed where both hide it); SheetD (x 1..3, "
        "y 1.5..3, z = 1) under a perforated fence card FenceC (x 0..2, y 1.5..3, z = 1.5; textures/fence_alpha.png "
        "16 x 12 times): its LS_buffer bits are added to SheetD's wedge coverage. %d triangles." % tris))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
