"""The organic paper-analog stages: creatures, plants and trees under a rect light.

Analogs of the test scenes of Shen, Feng and Yang's exponential soft shadow mapping (ESSM,
Table 1: ``ogre``, ``plants``, ``dinosaurs``) and of Schwarz and Stamminger 2008 (bitmask soft
shadows, Figs. 1, 8, 10 and Table 2: ``fig1_plant``, ``fig8_tree``, ``palm_dino``); the geometry
comes from :mod:`wsoft.stages.organic`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from pxr import Gf, Usd

from wsoft.stages.builders import (
    add_class_root,
    add_instance,
    add_material,
    add_mesh,
    add_rect_light,
    check_points_down,
    look_at_xform,
    make_stage,
    set_doc_string,
)
from wsoft.stages.mesh import MeshData, bounds32, flatten_below, merge_meshes, quad_mesh, triangle_count, zmin32
from wsoft.stages.organic.creatures import creature_at
from wsoft.stages.organic.plants import branch_tree, frond_mesh, leaf_cluster, plant_meshes, pot_mesh
from wsoft.stages.organic.tubes import lerp_profile, polyline, rounded, tube
from wsoft.stages.scenes import add_scene_camera


def ground(stage: Usd.Stage, half: float, center=(0.0, 0.0), color=(0.78, 0.76, 0.7)) -> int:
    """A single-sided square ``/World/Ground`` of half-side ``half`` at z = 0; its triangles."""
    cx, cy = center
    g = quad_mesh([(cx - half, cy - half, 0), (cx + half, cy - half, 0),
                   (cx + half, cy + half, 0), (cx - half, cy + half, 0)])
    add_mesh(stage, "/World/Ground", g, False,
             add_material(stage, "/World/Looks/GroundMat", color))
    return triangle_count(g[1])


def aimed_rect_light(stage: Usd.Stage, path: str, size: tuple[float, float],
                     pos: Sequence[float], target: Sequence[float], irradiance: float = 1.5
                     ) -> tuple[float, float]:
    """RectLight at `pos` aimed at `target`; intensity chosen so the irradiance
    at the target is about `irradiance` (intensity * area / d^2).  Returns
    (intensity, distance)."""
    w, h = size
    d = float(np.linalg.norm(np.asarray(pos, dtype=np.float64) - np.asarray(target)))
    intensity = round(irradiance * d * d / (w * h), 1)
    if abs(pos[0] - target[0]) < 1e-9 and abs(pos[1] - target[1]) < 1e-9:
        light = add_rect_light(stage, path, pos, float(w), float(h), intensity=intensity)  # identity rotation: emits -Z
        check_points_down(light.GetPrim(), (0, 0, -1), 0.999)
    else:
        light = add_rect_light(stage, path, look_at_xform(pos, target, (0.0, 0.0, 1.0)), float(w), float(h), intensity=intensity)
        check_points_down(light.GetPrim(), (0, 0, -1), 0.7)
    return intensity, d


def fmt_v(v: Sequence[float]) -> str:
    """A point as ``(x, y, z)`` to 3 decimals, for the stages' ``wsoft:doc``."""
    return "(" + ", ".join(f"{round(float(x), 3):g}" for x in v) + ")"


CREATURE_COLOR = (0.55, 0.5, 0.38)
LEAF_COLOR = (0.25, 0.55, 0.2)
STEM_COLOR = (0.35, 0.45, 0.2)
BARK_COLOR = (0.42, 0.3, 0.2)


def scene_ogre(out_dir: str) -> dict[str, object]:
    """ESSM's *Ogre* analog: one closed 135k-triangle creature under a small rect light: ``ogre.usdc``."""
    path = os.path.join(out_dir, "ogre.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    tris = ground(stage, 8.0)
    m, res = creature_at(130000, 140000, "ogre", 1101)
    if zmin32(m) != 0.0:
        raise RuntimeError("ogre does not touch the ground")
    add_mesh(stage, "/World/Ogre", m, False,
             add_material(stage, "/World/Looks/OgreMat", CREATURE_COLOR))
    ct = triangle_count(m[1])
    tris += ct
    lo, hi = bounds32(m)
    size = (0.7, 0.7)
    pos, target = (1.8, 2.8, 5.2), (0.2, 0.0, 1.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (3.0, -7.4, 5.6), (-0.4, -1.3, 0.5), (0, 0, 1), clip=(0.1, 200.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Ogre analog (Shen, Feng & Yang ESSM, Table 1 'Ogre'): one closed creature mesh "
        f"/World/Ogre of {ct} triangles (body, neck, horned head, four legs, tail: swept tubes "
        f"displaced by smooth seeded noise, resolution factor {res:g}), bounds {fmt_v(lo)} to "
        f"{fmt_v(hi)}, so {hi[2]:.3g} tall; its four feet are flattened onto the ground z = 0 "
        "(contact shadows). Ground /World/Ground 16 x 16 at z = 0. /World/Light: RectLight "
        f"{w:g} x {h:g} ({w / hi[2]:.2g} of the creature height) at {fmt_v(pos)} aimed at "
        f"{fmt_v(target)}, intensity {inten:g}; the penumbra is contact-sharp at the feet and "
        f"wide where the head's shadow falls. Total {tris} triangles."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_dinosaurs(out_dir: str) -> dict[str, object]:
    """ESSM's *Dinosaurs* analog: 4 instances of 2 creature prototypes: ``dinosaurs.usdc``."""
    path = os.path.join(out_dir, "dinosaurs.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    add_class_root(stage, "/Prototypes")
    protos = {}
    for name, kind, seed, color in (("Sauropod", "sauropod", 2201, (0.45, 0.5, 0.35)),
                                    ("Raptor", "raptor", 2202, (0.6, 0.45, 0.3))):
        m, res = creature_at(95000, 105000, kind, seed)
        ppath = "/Prototypes/" + name
        stage.DefinePrim(ppath, "Xform")
        add_mesh(stage, ppath + "/Mesh", m, False,
                 add_material(stage, ppath + "/Looks/Skin", color))
        protos[name] = (triangle_count(m[1]), res)
    tris = ground(stage, 12.0)
    stage.DefinePrim("/World/Dinosaurs", "Xform")
    placements = [  # (name, prototype, (x, y), rotateZ deg, uniform scale)
        ("Dino0", "Sauropod", (-2.2, 1.6), 20.0, 1.1),
        ("Dino1", "Raptor", (1.8, 2.2), 160.0, 0.9),
        ("Dino2", "Sauropod", (2.4, -1.9), -35.0, 0.85),
        ("Dino3", "Raptor", (-2.0, -2.4), 75.0, 1.0),
    ]
    inst_tris = 0
    for name, proto, (x, y), rz, sc in placements:
        add_instance(stage, "/World/Dinosaurs/" + name, "/Prototypes/" + proto, (x, y, 0.0), rz, sc)
        inst_tris += protos[proto][0]
    tris += inst_tris
    size = (1.2, 1.2)
    pos, target = (2.5, -3.5, 8.0), (0.0, 0.0, 0.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (6.5, -8.5, 6.0), (-0.4, 0.5, 0.6), (0, 0, 1), focal=28.0,
                     clip=(0.1, 300.0))
    (w, h), t_sauro, t_raptor = size, protos["Sauropod"][0], protos["Raptor"][0]
    set_doc_string(world, "wsoft:doc", (
        "Dinosaurs analog (Shen, Feng & Yang ESSM, Table 1 'Dinosaurs'): 4 instanceable Xforms "
        "/World/Dinosaurs/Dino0..3 referencing 2 creature prototypes under the class prim "
        f"/Prototypes (Sauropod {t_sauro} triangles, Raptor {t_raptor} triangles), placed with "
        "translate, rotateZ and uniform scale 0.85-1.1 (2 instances each); feet flattened onto "
        f"z = 0 (contact). Ground 24 x 24 at z = 0. /World/Light: RectLight {w:g} x {h:g} at "
        f"{fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total {tris} triangles "
        "counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": len(placements),
            "prototype_triangles": [protos["Sauropod"][0], protos["Raptor"][0]]}


def scene_plants(out_dir: str) -> dict[str, object]:
    """ESSM's *Plants* analog: 15 instances of 3 plant prototypes with overlapping leaves: ``plants.usdc``."""
    path = os.path.join(out_dir, "plants.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(3301)
    add_class_root(stage, "/Prototypes")
    leaf_mat = add_material(stage, "/Prototypes/Looks/LeafMat", LEAF_COLOR)
    stem_mat = add_material(stage, "/Prototypes/Looks/StemMat", STEM_COLOR)
    specs = [  # n_stems, height, spread, leaves per stem, leaf length, leaf width
        (8, 1.6, 0.55, 11, 0.55, 0.16),
        (6, 1.1, 0.45, 12, 0.45, 0.2),
        (10, 2.0, 0.7, 9, 0.6, 0.14),
    ]
    proto_tris, proto_top = [], []
    for k, (ns, h, sp, lps, ll, lw) in enumerate(specs):
        stems, leaves = plant_meshes(rng, ns, h, sp, lps, ll, lw, (10, 4), (24, 8), 0.025)
        ppath = f"/Prototypes/Plant{k}"
        stage.DefinePrim(ppath, "Xform")
        add_mesh(stage, ppath + "/Stems", stems, False, stem_mat)
        add_mesh(stage, ppath + "/Leaves", leaves, True, leaf_mat)
        proto_tris.append(triangle_count(stems[1]) + triangle_count(leaves[1]))
        proto_top.append(float(max(bounds32(stems)[1][2], bounds32(leaves)[1][2])))
    tris = ground(stage, 6.0)
    stage.DefinePrim("/World/Plants", "Xform")
    n_inst, inst_tris, top = 0, 0, 0.0
    for r in range(4):
        for c in range(4):
            proto = int(rng.integers(0, len(specs)))
            jit = rng.uniform(-0.25, 0.25, size=2)
            rz = float(np.round(rng.uniform(0.0, 360.0), 2))
            sc = float(np.round(rng.uniform(0.8, 1.25), 3))
            if (r, c) == (0, 3):
                continue
            x = round((c - 1.5) * 1.1 + float(jit[0]), 3)
            y = round((r - 1.5) * 1.1 + float(jit[1]), 3)
            add_instance(stage, f"/World/Plants/P_{r}_{c}", f"/Prototypes/Plant{proto}",
                         (x, y, 0.0), rz, sc)
            top = max(top, proto_top[proto] * sc)
            inst_tris += proto_tris[proto]
            n_inst += 1
    tris += inst_tris
    size = (1.0, 1.0)
    pos, target = (0.8, -0.6, 6.0), (0.0, 0.0, 0.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (4.5, -5.5, 4.5), (0.0, 0.0, 0.4), (0, 0, 1), focal=28.0,
                     clip=(0.1, 200.0))
    (w, h), ptris = size, ", ".join(str(t) for t in proto_tris)
    set_doc_string(world, "wsoft:doc", (
        f"Plants analog (Shen, Feng & Yang ESSM, Table 1 'Plants'): {n_inst} instanceable "
        "Xforms /World/Plants/P_r_c on a jittered 4 x 4 grid (1.1 apart, one corner empty) "
        "referencing 3 plant prototypes under the class prim /Prototypes (closed thin stem "
        "tubes plus double-sided curved leaf strips of 10 x 4 quads at many heights, so leaves "
        f"overlap in the light view at several depths; {ptris} triangles), rotateZ and uniform "
        f"scale 0.8-1.25, up to z = {top:.3g}. Ground 12 x 12 at z = 0. /World/Light: RectLight "
        f"{w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total "
        f"{tris} triangles counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": n_inst,
            "prototype_triangles": proto_tris}


def scene_fig1_plant(out_dir: str) -> dict[str, object]:
    """Schwarz & Stamminger's Fig. 1 analog: a potted plant under a large area light: ``fig1_plant.usdc``."""
    path = os.path.join(out_dir, "fig1_plant.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(4401)
    tris = ground(stage, 5.0)
    pot_h, pot_r = 0.35, 0.22
    pot = pot_mesh(pot_r, pot_h, 24, 48)
    stage.DefinePrim("/World/Plant", "Xform")
    add_mesh(stage, "/World/Plant/Pot", pot, False,
             add_material(stage, "/World/Looks/PotMat", (0.7, 0.4, 0.28)))
    stems, leaves = plant_meshes(rng, 13, 1.5, 0.55, 10, 0.42, 0.18, (14, 6), (48, 12), 0.018,
                                 base_z=pot_h - 0.01, base_spread=0.08)
    add_mesh(stage, "/World/Plant/Stems", stems, False,
             add_material(stage, "/World/Looks/StemMat", STEM_COLOR))
    add_mesh(stage, "/World/Plant/Leaves", leaves, True,
             add_material(stage, "/World/Looks/LeafMat", LEAF_COLOR))
    n_leaves = 13 * 10
    pt, st, lt = (triangle_count(m[1]) for m in (pot, stems, leaves))
    tris += pt + st + lt
    top = float(max(bounds32(leaves)[1][2], bounds32(stems)[1][2]))
    low = float(bounds32(leaves)[0][2])
    size = (1.6, 1.6)
    pos, target = (0.9, -0.7, 3.6), (0.0, 0.0, 0.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (2.3, -2.9, 2.2), (-0.25, 0.3, 0.45), (0, 0, 1), focal=28.0,
                     clip=(0.05, 100.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Schwarz & Stamminger 2008 Fig. 1 analog: a potted plant under a large area light. "
        f"/World/Plant/Pot (closed, {pt} triangles, radius {pot_r:g}, height {pot_h:g}, flat "
        f"base on z = 0), /World/Plant/Stems (13 closed stem tubes, {st} triangles) and "
        f"/World/Plant/Leaves ({n_leaves} double-sided curved leaves of 14 x 6 quads, {lt} "
        f"triangles) at heights from {low:.3g} up to {top:.3g}. Ground 10 x 10 at z = 0. "
        f"/World/Light: RectLight {w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, "
        f"intensity {inten:g}: penumbrae are sharp where the pot meets the ground and very "
        f"wide under the highest leaves. Total {tris} triangles."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_fig8_tree(out_dir: str) -> dict[str, object]:
    """Schwarz & Stamminger's Fig. 8 analog: a tree with instanced leaf clusters: ``fig8_tree.usdc``."""
    path = os.path.join(out_dir, "fig8_tree.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(5501)
    add_class_root(stage, "/Prototypes")
    leaf_mat = add_material(stage, "/Prototypes/Looks/LeafMat", (0.3, 0.5, 0.2))
    cl_tris = []
    for k in range(2):
        cl = leaf_cluster(rng, 140 + 30 * k, 0.45, 0.16, 0.07)
        ppath = f"/Prototypes/LeafCluster{k}"
        stage.DefinePrim(ppath, "Xform")
        add_mesh(stage, ppath + "/Leaves", cl, True, leaf_mat)
        cl_tris.append(triangle_count(cl[1]))
    tris = ground(stage, 8.0)
    parts: list[MeshData] = []
    tips: list[tuple[np.ndarray, float]] = []
    trunk_h = 2.0
    trunk_curve = polyline([(0, 0, -0.1), (0.05, 0.02, 0.8), (-0.05, 0.05, 1.5),
                            (0.0, 0.0, trunk_h)])
    trunk_prof = lerp_profile([0.32, 0.2, 0.17, 0.15])
    parts.append(tube(trunk_curve, rounded(trunk_prof, power=0.05, bump=0.08, seed=5502,
                                           fmax=6.0, kmax=6), 60, 24))
    top = trunk_curve(np.array([1.0]))[0]
    for c in range(4):
        az = 2 * math.pi * c / 4 + 0.4
        branch_tree(rng, top - [0, 0, 0.15 * c], (math.cos(az), math.sin(az), 0.9), 1.4,
                    0.12, 2, (24, 10), parts, tips)
    wood = flatten_below(merge_meshes(parts))
    stage.DefinePrim("/World/Tree", "Xform")
    add_mesh(stage, "/World/Tree/Wood", wood, False,
             add_material(stage, "/World/Looks/BarkMat", BARK_COLOR))
    wood_tris = triangle_count(wood[1])
    tris += wood_tris
    stage.DefinePrim("/World/Tree/Foliage", "Xform")
    for i, (p, ln) in enumerate(tips):
        k = i % 2
        sc = float(np.round(0.8 + 0.6 * min(ln, 1.0), 3))
        add_instance(stage, f"/World/Tree/Foliage/C{i:03d}", f"/Prototypes/LeafCluster{k}",
                     np.round(p, 4), float(np.round(rng.uniform(0, 360), 2)), sc)
        tris += cl_tris[k]
    hi = float(max(p[2] for p, _ in tips)) + 0.5
    size = (1.5, 1.5)
    pos, target = (2.0, -1.5, 7.0), (0.0, 0.0, 0.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (5.0, -6.5, 3.8), (-0.6, 0.6, 1.3), (0, 0, 1), focal=26.0,
                     clip=(0.1, 200.0))
    (w, h), ctris = size, ", ".join(str(t) for t in cl_tris)
    set_doc_string(world, "wsoft:doc", (
        f"Schwarz & Stamminger 2008 Fig. 8 analog: a tree. /World/Tree/Wood (trunk {trunk_h:g} "
        "tall with a flat base on z = 0, three levels of curved branches; one closed-tube mesh, "
        f"{wood_tris} triangles) and {len(tips)} instanceable leaf clusters "
        "/World/Tree/Foliage/Cnnn referencing 2 prototypes under the class prim /Prototypes "
        f"({ctris} triangles: balls of small double-sided leaves of 2 quads), up to about "
        f"z = {hi:.3g}. Ground 16 x 16 at z = 0. /World/Light: RectLight {w:g} x {h:g} at "
        f"{fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total {tris} triangles "
        "counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": len(tips),
            "prototype_triangles": cl_tris}




FROND_LEAFLETS = 44  # per side
DINO_AT, DINO_RZ = (-1.1, -0.9, 0.0), 10.0


def scene_palm_dino(out_dir: str) -> dict[str, object]:
    """Schwarz & Stamminger's Fig. 10 analog: a palm with instanced fronds over a creature: ``palm_dino.usdc``."""
    path = os.path.join(out_dir, "palm_dino.usdc")
    stage = make_stage("Z", path)
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(6601)
    add_class_root(stage, "/Prototypes")
    frond = frond_mesh(rng, 2.6, FROND_LEAFLETS)
    stage.DefinePrim("/Prototypes/Frond", "Xform")
    add_mesh(stage, "/Prototypes/Frond/Mesh", frond, True,
             add_material(stage, "/Prototypes/Frond/Looks/FrondMat", (0.3, 0.55, 0.2)))
    frond_tris = triangle_count(frond[1])
    tris = ground(stage, 9.0)
    # palm trunk: curved, ringed, flat base on z = 0
    crown = np.array([0.9, 0.4, 4.6])
    trunk_curve = polyline([(0, 0, -0.1), (0.1, 0.05, 1.5), (0.45, 0.2, 3.2), tuple(crown)])

    def trunk_r(t, th):
        r = (0.24 - 0.08 * t) * (1.0 + 0.06 * np.sin(2 * math.pi * 28 * t)) + 0.12 * np.maximum(
            0.0, 0.08 - t)
        r = r * np.minimum(1.0, np.sin(math.pi * t) * 15.0) ** 0.5
        return np.broadcast_to(r, np.broadcast(t, th).shape).copy()

    trunk = flatten_below(tube(trunk_curve, trunk_r, 140, 24))
    stage.DefinePrim("/World/Palm", "Xform")
    add_mesh(stage, "/World/Palm/Trunk", trunk, False,
             add_material(stage, "/World/Looks/BarkMat", BARK_COLOR))
    trunk_tris = triangle_count(trunk[1])
    tris += trunk_tris
    stage.DefinePrim("/World/Palm/Fronds", "Xform")
    n_fronds = 14
    for i in range(n_fronds):
        az = 360.0 * i / n_fronds + float(np.round(rng.uniform(-8, 8), 2))
        sc = float(np.round(rng.uniform(0.85, 1.15), 3))
        add_instance(stage, f"/World/Palm/Fronds/F{i:02d}", "/Prototypes/Frond",
                     np.round(crown - [0, 0, 0.05 * (i % 3)], 4), az, sc)
        tris += frond_tris
    dino, _res = creature_at(25000, 35000, "sauropod", 6602)
    dino_tris = triangle_count(dino[1])
    dpath = "/World/Dino"
    dm = add_mesh(stage, dpath, dino, False,
                  add_material(stage, "/World/Looks/DinoMat", (0.5, 0.48, 0.36)))
    dm.AddTranslateOp().Set(Gf.Vec3d(*DINO_AT))
    dm.AddRotateZOp().Set(DINO_RZ)
    tris += dino_tris
    size = (1.4, 1.4)
    pos, target = (1.8, -1.2, 9.5), (0.3, 0.3, 0.0)
    inten, _ = aimed_rect_light(stage, "/World/Light", size, pos, target)
    add_scene_camera(stage, (5.5, -8.0, 4.5), (-0.3, 0.6, 1.8), (0, 0, 1), focal=26.0,
                     clip=(0.1, 200.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Schwarz & Stamminger 2008 Fig. 10 analog: a palm over a dinosaur. /World/Palm/Trunk "
        f"(curved ringed closed tube, flat base on z = 0, crown at {fmt_v(crown)}, {trunk_tris} "
        f"triangles), {n_fronds} instanceable fronds /World/Palm/Fronds/Fnn referencing the "
        f"class prototype /Prototypes/Frond ({frond_tris} triangles: drooping rachis tube plus "
        f"{2 * FROND_LEAFLETS} double-sided leaflets, scale 0.85-1.15), and /World/Dino (closed "
        f"sauropod creature, {dino_tris} triangles, translate {fmt_v(DINO_AT)}, rotateZ "
        f"{DINO_RZ:g}, feet flattened onto z = 0). Ground 18 x 18 at z = 0. /World/Light: "
        f"RectLight {w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, intensity "
        f"{inten:g}. Total {tris} triangles counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": n_fronds,
            "prototype_triangles": [frond_tris]}
