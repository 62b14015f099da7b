"""``forest``: about 10,000 trees placed by one PointInstancer (4 prototypes of about 5,500
triangles each, over 50M instanced triangles) on a 240 x 240 ground: scale for instanced geometry."""

from __future__ import annotations

import math
import os

import numpy as np
from pxr import Gf, Sdf, UsdGeom, Vt

from wsoft.stages.builders import (
    add_cutout_material,
    add_material,
    add_mesh,
    add_rect_light,
    add_sun,
    check_points_down,
    make_stage,
    set_doc_string,
)
from wsoft.stages.mesh import MeshData, grid_quad_mesh, triangle_count
from wsoft.stages.scenes import add_scene_camera
from wsoft.stages.textures import write_checker_png


# (name, trunk radius, trunk height, crown shape, crown centre z, crown radii (xy, z), leaf size,
#  leaf quads, cutout leaves)
FOREST_PROTOTYPES = [
    ("Pine", 0.16, 7.0, "cone", 4.8, (1.5, 3.4), 0.30, 2710, False),
    ("Oak", 0.26, 3.6, "ellipsoid", 5.2, (2.2, 1.9), 0.34, 2720, False),
    ("Birch", 0.12, 6.2, "ellipsoid", 5.6, (1.2, 2.3), 0.36, 2600, True),
    ("Shrub", 0.10, 1.2, "ellipsoid", 1.7, (1.3, 1.0), 0.26, 2500, False),
]
FOREST_GRID = 101          # trees on a jittered FOREST_GRID x FOREST_GRID grid
FOREST_HALF = 120.0        # the ground spans [-FOREST_HALF, FOREST_HALF]^2 (the trees a little less)
FOREST_INVISIBLE = (17, 2024, 5151, 7777, 9000, 10100)  # invisibleIds


def leaf_quads(rng: np.random.Generator, n: int, shape: str, zc: float, rxy: float, rz: float,
               size: float) -> tuple[np.ndarray, list[int], list[int], np.ndarray]:
    """n small leaf quads of side about `size`, randomly turned, filling a crown (a cone standing on
    zc - rz, or an ellipsoid about zc). Returns a mesh tuple and faceVarying st (4 n, 2)."""
    if shape == "cone":
        h = rng.uniform(0.0, 1.0, n) ** 0.7  # more leaves low in the cone, where it is wide
        z = zc - rz + 2.0 * rz * h
        rmax = rxy * (1.0 - h) + 0.15
        r = rmax * np.sqrt(rng.uniform(0.15, 1.0, n))
    else:
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        rad = rng.uniform(0.45, 1.0, n) ** (1.0 / 3.0)
        z = zc + rz * rad * d[:, 2]
        r = rxy * rad * np.hypot(d[:, 0], d[:, 1])
    th = rng.uniform(0.0, 2.0 * math.pi, n)
    c = np.stack([r * np.cos(th), r * np.sin(th), z], axis=1)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    a = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    u = np.cross(nrm, a)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(nrm, u)
    s = size * rng.uniform(0.7, 1.3, (n, 1)) * 0.5
    pts = np.stack([c - s * u - s * v, c + s * u - s * v, c + s * u + s * v, c - s * u + s * v], axis=1)
    st = np.tile(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), (n, 1))
    return pts.reshape(-1, 3), [4] * n, list(range(4 * n)), st


def trunk_mesh(radius: float, height: float, segments: int = 16, rings: int = 6) -> MeshData:
    """Closed tapered cylinder standing on z = 0: side quads in `rings` bands, n-gon caps, wound outward."""
    th = 2.0 * math.pi * np.arange(segments) / segments
    pts = []
    for k in range(rings + 1):
        z = height * k / rings
        r = radius * (1.0 - 0.45 * k / rings)
        pts += [(r * math.cos(t), r * math.sin(t), z) for t in th]
    counts, idx = [segments, segments], list(range(segments))[::-1] + [rings * segments + j for j in range(segments)]
    for k in range(rings):
        for j in range(segments):
            j1 = (j + 1) % segments
            counts.append(4)
            idx += [k * segments + j, k * segments + j1, (k + 1) * segments + j1, (k + 1) * segments + j]
    return np.asarray(pts, dtype=np.float64), counts, idx


def scene_forest(out_dir: str) -> dict[str, object]:
    """About 10,000 trees placed by one PointInstancer (4 prototypes of ~5,500 triangles each,
    over 50M instanced triangles) on a 240 x 240 ground: scale for instanced geometry."""
    path = os.path.join(out_dir, "forest.usdc")
    write_checker_png(os.path.join(out_dir, "textures", "checker_alpha.png"))
    stage = make_stage("Z", path)
    rng = np.random.default_rng(20250214)

    ground = grid_quad_mesh((-FOREST_HALF, -FOREST_HALF, 0.0), (2 * FOREST_HALF, 0.0, 0.0),
                            (0.0, 2 * FOREST_HALF, 0.0), 8, 8)
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.36, 0.3, 0.22)))
    ground_tris = triangle_count(ground[1])

    pi = UsdGeom.PointInstancer.Define(stage, "/World/Forest")
    protos_root = "/World/Forest/Prototypes"
    UsdGeom.Scope.Define(stage, protos_root)
    bark = add_material(stage, "/World/Looks/Bark", (0.35, 0.25, 0.16))
    proto_paths, proto_tris = [], []
    for k, (name, tr, th, shape, zc, (rxy, rz), leaf, nleaf, cutout) in enumerate(FOREST_PROTOTYPES):
        root = "%s/%s" % (protos_root, name)
        xf = UsdGeom.Xform.Define(stage, root)
        if name == "Oak":  # a prototype with its own transform on its root
            xf.AddRotateZOp().Set(30.0)
            xf.AddScaleOp().Set(Gf.Vec3f(1.1, 1.1, 1.0))
        trunk = trunk_mesh(tr, th)
        add_mesh(stage, root + "/Trunk", trunk, False, bark)
        crown_parent = root
        if name == "Shrub":  # a nested child transform inside a prototype
            crown_parent = root + "/Crown"
            UsdGeom.Xform.Define(stage, crown_parent).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.2))
        pts, counts, idx, st = leaf_quads(rng, nleaf, shape, zc, rxy, rz, leaf)
        green = (0.18 + 0.05 * k, 0.42 - 0.03 * k, 0.16)
        if cutout:
            mat = add_cutout_material(stage, "/World/Looks/%sLeaves" % name, green, "textures/checker_alpha.png")
        else:
            mat = add_material(stage, "/World/Looks/%sLeaves" % name, green)
        add_mesh(stage, crown_parent + "/Leaves", (pts, counts, idx), True, mat, st=st)
        proto_paths.append(Sdf.Path(root))
        proto_tris.append(triangle_count(trunk[1]) + triangle_count(counts))
    pi.CreatePrototypesRel().SetTargets(proto_paths)

    n = FOREST_GRID * FOREST_GRID
    spacing = 2.0 * (FOREST_HALF - 6.0) / (FOREST_GRID - 1)
    gx, gy = np.meshgrid(np.arange(FOREST_GRID), np.arange(FOREST_GRID))
    xy = (np.stack([gx.ravel(), gy.ravel()], axis=1) - (FOREST_GRID - 1) / 2.0) * spacing
    xy += rng.uniform(-0.4, 0.4, (n, 2)) * spacing
    proto = rng.choice(len(FOREST_PROTOTYPES), size=n, p=[0.35, 0.25, 0.25, 0.15]).astype(np.int32)
    yaw = rng.uniform(0.0, 2.0 * math.pi, n)
    tilt = rng.normal(0.0, math.radians(3.0), n)
    tilt_dir = rng.uniform(0.0, 2.0 * math.pi, n)
    # orientation = (yaw about Z) then (a small tilt about a horizontal axis), as quaternions (w, x, y, z)
    qz = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=1)
    qt = np.stack([np.cos(tilt / 2), np.sin(tilt / 2) * np.cos(tilt_dir), np.sin(tilt / 2) * np.sin(tilt_dir), 0 * tilt], axis=1)
    w1, v1 = qt[:, :1], qt[:, 1:]
    w2, v2 = qz[:, :1], qz[:, 1:]
    q = np.concatenate([w1 * w2 - np.sum(v1 * v2, axis=1, keepdims=True), w1 * v2 + w2 * v1 + np.cross(v1, v2)], axis=1)
    scale = np.round(rng.uniform(0.75, 1.3, n), 3)
    sc = np.stack([scale, scale, scale * np.round(rng.uniform(0.9, 1.15, n), 3)], axis=1)
    pos = np.concatenate([np.round(xy, 3), np.zeros((n, 1))], axis=1)
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(proto))
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pos, dtype=np.float32)))
    pi.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(*map(float, r)) for r in q]))
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(sc, dtype=np.float32)))
    pi.CreateInvisibleIdsAttr(Vt.Int64Array(list(FOREST_INVISIBLE)))
    shown = np.ones(n, bool)
    shown[list(FOREST_INVISIBLE)] = False
    inst_tris = int(np.asarray(proto_tris)[proto[shown]].sum())

    stage.DefinePrim("/World/Lights", "Xform")
    sun = add_sun(stage, "/World/Lights/Sun", 1.5, (35.0, 0.0, 40.0), intensity=3.0)
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)
    rect = add_rect_light(stage, "/World/Lights/Rect", (0.0, 0.0, 90.0), 12.0, 12.0, intensity=4000.0)
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.999)

    add_scene_camera(stage, (-150.0, -170.0, 70.0), (10.0, 15.0, 0.0), (0.0, 0.0, 1.0),
                     focal=24.0, clip=(0.5, 2000.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc",
                   "forest: %d trees (PointInstancer /World/Forest, %d invisibleIds) of %d prototypes "
                   "(%s triangles), %d instanced triangles; ground %gx%g"
                   % (int(shown.sum()), len(FOREST_INVISIBLE), len(FOREST_PROTOTYPES),
                      ", ".join(str(t) for t in proto_tris), inst_tris, 2 * FOREST_HALF, 2 * FOREST_HALF))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": ground_tris + inst_tris, "instances": int(shown.sum()),
            "prototype_triangles": proto_tris}
