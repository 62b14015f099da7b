#!/usr/bin/env python3
"""Deterministic generator for the wsoft USD test scenes.

Usage::

    python usd_scenes/generate.py [--out DIR] [--only NAME ...]

NAME is one of: box_plane, contact, multi_light, cutout, city, penumbra_ramp,
lightmapped_bridge, tower, tunnel_fan, forest, ogre, plants, dinosaurs, fig1_plant,
fig8_tree, palm_dino, fence_perforated, fence_mesh, hl2_like, factory, greece
(a file name with extension is accepted too).  The organic paper-analog scenes
(ogre ... palm_dino: creatures, plants, trees) are built by ``organic.py``; the
soft textured shadow volume analogs (fence_perforated ... greece) by
``stsv_scenes.py``.
The default output folder is the folder holding this script.  Every run with
the same arguments writes byte-identical files: all randomness uses fixed
seeds and nothing time-dependent is written.

Only pxr (usd-core), numpy and Pillow are used.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from PIL import Image
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

# ---------------------------------------------------------------------------
# Geometry helpers.  A "mesh tuple" is (points (N,3) float64, counts, indices).
# All closed meshes are wound counter-clockwise seen from outside (normals out).
# ---------------------------------------------------------------------------

MeshData = Tuple[np.ndarray, List[int], List[int]]


def box_mesh(lo: Sequence[float], hi: Sequence[float]) -> MeshData:
    """Axis-aligned box as 6 outward-facing quads (8 shared points)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    pts = np.empty((8, 3), dtype=np.float64)
    for i in range(8):  # bit 0 -> x, bit 1 -> y, bit 2 -> z
        pts[i] = [hi[0] if i & 1 else lo[0],
                  hi[1] if i & 2 else lo[1],
                  hi[2] if i & 4 else lo[2]]
    faces = [
        (0, 2, 3, 1),  # -Z
        (4, 5, 7, 6),  # +Z
        (0, 1, 5, 4),  # -Y
        (2, 6, 7, 3),  # +Y
        (0, 4, 6, 2),  # -X
        (1, 3, 7, 5),  # +X
    ]
    return pts, [4] * 6, [i for f in faces for i in f]


def frame_box_mesh(origin: Sequence[float], ex: Sequence[float], ey: Sequence[float],
                   ez: Sequence[float]) -> MeshData:
    """Parallelepiped origin + [0, 1] * ex + [0, 1] * ey + [0, 1] * ez as 6 quads (8 points).

    It uses `box_mesh`'s point order and faces, so it is wound outward when
    (ex, ey, ez) is right-handed (det > 0), as for the axis-aligned box.
    """
    o = np.asarray(origin, dtype=np.float64)
    e = [np.asarray(v, dtype=np.float64) for v in (ex, ey, ez)]
    if float(np.dot(np.cross(e[0], e[1]), e[2])) <= 0.0:
        raise ValueError("frame_box_mesh: edges must be right-handed")
    pts = np.empty((8, 3), dtype=np.float64)
    for i in range(8):  # bit 0 -> ex, bit 1 -> ey, bit 2 -> ez
        pts[i] = o + (i & 1) * e[0] + ((i >> 1) & 1) * e[1] + ((i >> 2) & 1) * e[2]
    _, counts, idx = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    return pts, counts, idx


def bar_mesh(p0: Sequence[float], p1: Sequence[float], thickness: float) -> MeshData:
    """Thin closed box with a square thickness x thickness cross-section whose axis runs
    from p0 to p1 (its end faces lie in the planes through p0 and p1).  8 points, 6 quads,
    wound outward.  The cross-section is turned so that one side is horizontal (for a
    nearly vertical bar: perpendicular to X)."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    d = p1 - p0
    u = d / math.sqrt(float(np.dot(d, d)))
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    a = np.cross(u, ref)
    a /= math.sqrt(float(np.dot(a, a)))
    b = np.cross(u, a)  # a x b = u: (a, b, d) is right-handed
    t = float(thickness)
    return frame_box_mesh(p0 - 0.5 * t * (a + b), t * a, t * b, d)


def quad_mesh(corners: Sequence[Sequence[float]]) -> MeshData:
    """Single quad from 4 corners given in counter-clockwise order."""
    return np.asarray(corners, dtype=np.float64), [4], [0, 1, 2, 3]


def uv_sphere_y(radius: float, segments: int, stacks: int) -> MeshData:
    """Triangle UV sphere centred at the origin with its poles on the Y axis.

    The bottom pole is a vertex at (0, -radius, 0), so the sphere touches a
    ground plane y = -radius in exactly one point.
    """
    pts = [(0.0, radius, 0.0)]
    for k in range(1, stacks):
        phi = math.pi * k / stacks  # from +Y (0) to -Y (pi)
        y = radius * math.cos(phi)
        r = radius * math.sin(phi)
        for s in range(segments):
            th = 2.0 * math.pi * s / segments
            pts.append((r * math.cos(th), y, -r * math.sin(th)))
    pts.append((0.0, -radius, 0.0))
    top, bottom = 0, len(pts) - 1

    def ring(k: int, s: int) -> int:  # k in 1..stacks-1
        return 1 + (k - 1) * segments + (s % segments)

    idx: List[int] = []
    for s in range(segments):
        idx += [top, ring(1, s), ring(1, s + 1)]
    for k in range(1, stacks - 1):
        for s in range(segments):
            a, b = ring(k, s), ring(k, s + 1)
            c, d = ring(k + 1, s + 1), ring(k + 1, s)
            idx += [a, d, c, a, c, b]
    for s in range(segments):
        idx += [bottom, ring(stacks - 1, s + 1), ring(stacks - 1, s)]
    return np.asarray(pts, dtype=np.float64), [3] * (len(idx) // 3), idx


def prism_z(n: int, radius: float, z0: float, z1: float,
            center: Sequence[float] = (0.0, 0.0), phase: float = 0.0) -> MeshData:
    """Right prism with regular n-gon caps (n-gon faces kept as single faces)."""
    cx, cy = center
    th = [phase + 2.0 * math.pi * k / n for k in range(n)]
    bot = [(cx + radius * math.cos(t), cy + radius * math.sin(t), z0) for t in th]
    top = [(cx + radius * math.cos(t), cy + radius * math.sin(t), z1) for t in th]
    pts = np.asarray(bot + top, dtype=np.float64)
    counts: List[int] = []
    idx: List[int] = []
    counts.append(n)
    idx += list(range(n))[::-1]  # bottom cap, facing -Z
    counts.append(n)
    idx += [n + k for k in range(n)]  # top cap, facing +Z
    for k in range(n):
        k1 = (k + 1) % n
        counts.append(4)
        idx += [k, k1, n + k1, n + k]
    return pts, counts, idx


def torus_z(major: float, minor: float, nu: int, nv: int) -> MeshData:
    """Quad torus around the Z axis, centred at the origin."""
    pts = []
    for i in range(nu):
        u = 2.0 * math.pi * i / nu
        for j in range(nv):
            v = 2.0 * math.pi * j / nv
            rr = major + minor * math.cos(v)
            pts.append((rr * math.cos(u), rr * math.sin(u), minor * math.sin(v)))
    idx: List[int] = []
    for i in range(nu):
        for j in range(nv):
            a = i * nv + j
            b = ((i + 1) % nu) * nv + j
            c = ((i + 1) % nu) * nv + (j + 1) % nv
            d = i * nv + (j + 1) % nv
            idx += [a, b, c, d]
    return np.asarray(pts, dtype=np.float64), [4] * (nu * nv), idx


def translate_mesh(m: MeshData, t: Sequence[float]) -> MeshData:
    return m[0] + np.asarray(t, dtype=np.float64), m[1], m[2]


def merge_meshes(parts: Sequence[MeshData]) -> MeshData:
    pts, counts, idx, off = [], [], [], 0
    for p, c, i in parts:
        pts.append(p)
        counts += list(c)
        idx += [k + off for k in i]
        off += len(p)
    return np.concatenate(pts, axis=0), counts, idx


def weld(m: MeshData) -> MeshData:
    """Merge points with bit-identical float32 coordinates (deterministic)."""
    p32 = m[0].astype(np.float32)
    uniq, inverse = np.unique(p32, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    idx = [int(inverse[i]) for i in m[2]]
    return uniq.astype(np.float64), list(m[1]), idx


def triangle_count(counts: Sequence[int]) -> int:
    return int(sum(c - 2 for c in counts))


def signed_volume(m: MeshData) -> float:
    p, counts, idx = m
    vol, o = 0.0, 0
    for c in counts:
        f = idx[o:o + c]
        for k in range(1, c - 1):
            vol += float(np.dot(p[f[0]], np.cross(p[f[k]], p[f[k + 1]])))
        o += c
    return vol / 6.0


def grid_quad_mesh(origin: Sequence[float], u: Sequence[float], v: Sequence[float],
                   nu: int, nv: int) -> MeshData:
    """Planar nu x nv grid of quads spanning origin + [0, 1] * u + [0, 1] * v.

    The quads are wound counter-clockwise seen from the side u x v points to.
    """
    o = np.asarray(origin, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    a = np.linspace(0.0, 1.0, nu + 1)
    b = np.linspace(0.0, 1.0, nv + 1)
    pts = o + a[None, :, None] * u + b[:, None, None] * v  # (nv+1, nu+1, 3)
    idx: List[int] = []
    for j in range(nv):
        for i in range(nu):
            p0 = j * (nu + 1) + i
            idx += [p0, p0 + 1, p0 + nu + 2, p0 + nu + 1]
    return pts.reshape(-1, 3), [4] * (nu * nv), idx


def grid_box_mesh(lo: Sequence[float], hi: Sequence[float], n: Sequence[int]) -> MeshData:
    """Axis-aligned closed box whose faces are grids of n[0] x n[1] x n[2] cells.

    All six faces take their coordinates from the same per-axis arrays, so the
    points along shared edges are bit-identical and `weld` joins them into one
    closed, outward-wound surface.
    """
    vals = [np.linspace(float(lo[k]), float(hi[k]), int(n[k]) + 1) for k in range(3)]
    parts: List[MeshData] = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3  # e_b x e_c = +e_a
        vb, vc = vals[b], vals[c]
        nb, nc = len(vb), len(vc)
        for side, val in ((-1, float(lo[a])), (1, float(hi[a]))):
            pts = np.empty((nc, nb, 3), dtype=np.float64)
            pts[:, :, a] = val
            pts[:, :, b] = vb[None, :]
            pts[:, :, c] = vc[:, None]
            idx: List[int] = []
            for j in range(nc - 1):
                for i in range(nb - 1):
                    p0 = j * nb + i
                    q = [p0, p0 + 1, p0 + nb + 1, p0 + nb]  # normal +e_a
                    idx += q if side > 0 else q[::-1]
            parts.append((pts.reshape(-1, 3), [4] * ((nb - 1) * (nc - 1)), idx))
    return weld(merge_meshes(parts))


def z_sphere(radius: float, segments: int, stacks: int) -> MeshData:
    """`uv_sphere_y` turned so its poles lie on the Z axis (bottom pole at z = -radius)."""
    p, counts, idx = uv_sphere_y(radius, segments, stacks)
    # rotation of +90 degrees about X: (x, y, z) -> (x, -z, y), keeps the winding outward
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1), counts, idx


def check_closed(m: MeshData, what: str) -> None:
    """Raise unless every directed edge appears once with its reverse once and the
    enclosed volume is positive (closed, consistently wound, normals out)."""
    _, counts, idx = m
    edges = set()
    o = 0
    for c in counts:
        f = idx[o:o + c]
        for k in range(c):
            e = (f[k], f[(k + 1) % c])
            if e in edges:
                raise RuntimeError("%s: directed edge %s used twice" % (what, e))
            edges.add(e)
        o += c
    if any((b, a) not in edges for a, b in edges):
        raise RuntimeError("%s: mesh is not closed" % what)
    if signed_volume(m) <= 0.0:
        raise RuntimeError("%s: mesh is wound inward" % what)


def face_normals(m: MeshData) -> np.ndarray:
    """Unit normal of every face (Newell's method), as (F, 3)."""
    p, counts, idx = m
    out = np.zeros((len(counts), 3), dtype=np.float64)
    o = 0
    for f, c in enumerate(counts):
        q = p[idx[o:o + c]]
        r = np.roll(q, -1, axis=0)
        n = np.array([np.sum((q[:, 1] - r[:, 1]) * (q[:, 2] + r[:, 2])),
                      np.sum((q[:, 2] - r[:, 2]) * (q[:, 0] + r[:, 0])),
                      np.sum((q[:, 0] - r[:, 0]) * (q[:, 1] + r[:, 1]))])
        out[f] = n / math.sqrt(float(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]))
        o += c
    return out


# ---------------------------------------------------------------------------
# Baked lighting: per-vertex irradiance with static-geometry shadows.
# ---------------------------------------------------------------------------


def segments_blocked(p0: np.ndarray, p1: np.ndarray,
                     boxes: Sequence[Tuple[Sequence[float], Sequence[float]]]) -> np.ndarray:
    """(N,) bool: does the segment p0[i] -> p1[i] meet any axis-aligned box?

    Slab test with the segment parameterised t in [0, 1]; a segment that
    starts inside a box counts as blocked.
    """
    d = p1 - p0
    blocked = np.zeros(len(p0), dtype=bool)
    par = d == 0.0
    safe = np.where(par, 1.0, d)
    for lo, hi in boxes:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        ta = (lo - p0) / safe
        tb = (hi - p0) / safe
        inside = (p0 >= lo) & (p0 <= hi)
        tmin = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
        tmax = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
        tnear = np.max(tmin, axis=1)
        tfar = np.min(tmax, axis=1)
        blocked |= (tnear <= tfar) & (tfar > 0.0) & (tnear < 1.0)
    return blocked


BAKE_AMBIENT = 0.05
BAKE_OFFSET = 1e-3  # start of the shadow segment, along the face normal
BAKE_SUN_FAR = 1000.0  # length of the shadow segment toward a distant light


def bake_vertex_irradiance(m: MeshData, lights: Sequence[Dict[str, object]],
                           boxes: Sequence[Tuple[Sequence[float], Sequence[float]]]) -> np.ndarray:
    """Per-vertex RGB irradiance (V, 3) of a static mesh.

    For every face corner, with the face normal n:
      E = sum over lights of color * weight * max(0, n.l) * falloff * visibility,
    where a "distant" light has weight = intensity and falloff 1, and a
    "sphere" light is a point at its centre with weight = intensity * pi * r^2
    and falloff 1 / d^2.  Visibility is a segment-vs-box test against the
    static boxes only.  A vertex gets the mean over its face corners, plus the
    constant BAKE_AMBIENT.  Values are rounded to 4 decimals.
    """
    pts = np.asarray(m[0], dtype=np.float32).astype(np.float64)  # as written
    counts, idx = m[1], m[2]
    fn = face_normals((pts, counts, idx))
    corner_v = np.asarray(idx, dtype=np.int64)
    corner_n = np.repeat(fn, np.asarray(counts, dtype=np.int64), axis=0)
    p = pts[corner_v]
    start = p + BAKE_OFFSET * corner_n
    e = np.zeros((len(p), 3), dtype=np.float64)
    for light in lights:
        color = np.asarray(light["color"], dtype=np.float64)
        if light["kind"] == "distant":
            to_l = np.broadcast_to(np.asarray(light["to_light"], dtype=np.float64), p.shape)
            end = start + BAKE_SUN_FAR * to_l
            falloff = np.ones(len(p))
            weight = float(light["intensity"])
        else:
            c = np.asarray(light["position"], dtype=np.float64)
            dv = c - p
            d2 = dv[:, 0] * dv[:, 0] + dv[:, 1] * dv[:, 1] + dv[:, 2] * dv[:, 2]
            to_l = dv / np.sqrt(d2)[:, None]
            end = np.broadcast_to(c, p.shape)
            falloff = 1.0 / d2
            r = float(light["radius"])
            weight = float(light["intensity"]) * math.pi * r * r
        cos = (corner_n[:, 0] * to_l[:, 0] + corner_n[:, 1] * to_l[:, 1]
               + corner_n[:, 2] * to_l[:, 2])
        vis = ~segments_blocked(start, end, boxes)
        term = weight * np.maximum(cos, 0.0) * falloff * vis
        e += term[:, None] * color[None, :]
    total = np.zeros((len(pts), 3), dtype=np.float64)
    np.add.at(total, corner_v, e)
    n_corners = np.bincount(corner_v, minlength=len(pts)).astype(np.float64)
    out = total / np.maximum(n_corners, 1.0)[:, None] + BAKE_AMBIENT
    return np.round(out, 4)


# ---------------------------------------------------------------------------
# USD helpers
# ---------------------------------------------------------------------------


def new_stage(path: str, up_axis: str) -> Usd.Stage:
    if os.path.exists(path):
        os.remove(path)
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up_axis == "Z" else UsdGeom.Tokens.y)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    return stage


def make_material(stage: Usd.Stage, path: str, color: Sequence[float],
                  roughness: float = 0.7) -> UsdShade.Material:
    looks = Sdf.Path(path).GetParentPath()
    if not stage.GetPrimAtPath(looks):
        UsdGeom.Scope.Define(stage, looks)
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, path + "/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(roughness))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def bind(prim: Usd.Prim, mat: UsdShade.Material) -> None:
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)


def make_mesh(stage: Usd.Stage, path: str, m: MeshData, double_sided: bool,
              material: Optional[UsdShade.Material] = None) -> UsdGeom.Mesh:
    pts, counts, idx = m
    mesh = UsdGeom.Mesh.Define(stage, path)
    p32 = np.ascontiguousarray(pts, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(p32))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.asarray(counts, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(idx, dtype=np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateDoubleSidedAttr(bool(double_sided))
    lo, hi = p32.min(axis=0), p32.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    if material is not None:
        bind(mesh.GetPrim(), material)
    return mesh


def look_at_xform(eye: Sequence[float], target: Sequence[float],
                  up: Sequence[float]) -> Gf.Matrix4d:
    """Local-to-world matrix of an object at `eye` whose local -Z looks at
    `target` with local +Y as close as possible to `up`."""
    view = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(*up))
    return view.GetInverse()


def make_camera(stage: Usd.Stage, eye, target, up, aspect: str = "4:3",
                focal: float = 24.0, clip=(0.1, 1000.0)) -> UsdGeom.Camera:
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    cam.CreateFocalLengthAttr(float(focal))
    if aspect == "1:1":
        cam.CreateHorizontalApertureAttr(24.0)
        cam.CreateVerticalApertureAttr(24.0)
    else:
        cam.CreateHorizontalApertureAttr(36.0)
        cam.CreateVerticalApertureAttr(27.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(float(clip[0]), float(clip[1])))
    cam.AddTransformOp().Set(look_at_xform(eye, target, up))
    return cam


def world_dir(prim: Usd.Prim, d=(0.0, 0.0, -1.0)) -> Gf.Vec3d:
    m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    return m.TransformDir(Gf.Vec3d(*d)).GetNormalized()


def check_points_down(prim: Usd.Prim, down: Sequence[float], min_cos: float = 0.5) -> None:
    d = world_dir(prim)
    c = float(Gf.Dot(d, Gf.Vec3d(*down)))
    if c < min_cos:
        raise RuntimeError("%s: world -Z = %s does not point down (cos=%.3f)"
                           % (prim.GetPath(), d, c))


def set_doc_attr(prim: Usd.Prim, name: str, value: float) -> None:
    attr = prim.CreateAttribute(name, Sdf.ValueTypeNames.Double, custom=True)
    attr.Set(float(value))


def set_doc_string(prim: Usd.Prim, name: str, value: str) -> None:
    prim.CreateAttribute(name, Sdf.ValueTypeNames.String, custom=True).Set(value)


def set_custom_bool(prim: Usd.Prim, name: str, value: bool) -> None:
    prim.CreateAttribute(name, Sdf.ValueTypeNames.Bool, custom=True).Set(bool(value))


def set_display_color(mesh: UsdGeom.Mesh, color: Sequence[float]) -> None:
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(
        Vt.Vec3fArray([Gf.Vec3f(*map(float, color))]))


# ---------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------


def mark_casters(stage: Usd.Stage, paths: Sequence[str]) -> None:
    """Mark the occluders of a test scene as the *dynamic casters* of Salzman's method
    (``wsoft:dynamic = true``); the ground stays a static receiver. Other techniques ignore it."""
    for path in paths:
        stage.GetPrimAtPath(path).CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool, custom=True).Set(True)


def scene_box_plane(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "box_plane.usda")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    set_doc_attr(world, "wsoft:analytic:occluder_height", 1.0)
    set_doc_attr(world, "wsoft:analytic:light_height", 3.0)
    set_doc_attr(world, "wsoft:analytic:occluder_half", 1.0)
    set_doc_attr(world, "wsoft:analytic:light_half", 0.5)

    ground_mat = make_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8))
    occ_mat = make_material(stage, "/World/Looks/OccluderMat", (0.8, 0.25, 0.2))
    ground = quad_mesh([(-10, -10, 0), (10, -10, 0), (10, 10, 0), (-10, 10, 0)])
    occluder = quad_mesh([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)])
    make_mesh(stage, "/World/Ground", ground, False, ground_mat)
    make_mesh(stage, "/World/Occluder", occluder, True, occ_mat)

    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(1.0)
    light.CreateHeightAttr(1.0)
    light.CreateIntensityAttr(10.0)
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 3.0))  # identity rotation: emits -Z
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    make_camera(stage, (0.0, -6.0, 9.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), clip=(0.1, 100.0))
    mark_casters(stage, ['/World/Occluder'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": triangle_count(ground[1]) + triangle_count(occluder[1])}


def scene_contact(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "contact.usda")
    stage = new_stage(path, "Y")
    tris = 0

    ground = quad_mesh([(-6, 0, 6), (6, 0, 6), (6, 0, -6), (-6, 0, -6)])  # faces +Y
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris += triangle_count(ground[1])

    # Unit cube, bottom face on y = 0, occupying x in [1, 2], z in [-0.5, 0.5].
    cube = box_mesh((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
    cube_prim = make_mesh(stage, "/World/Cube", cube, False,
                          make_material(stage, "/World/Looks/CubeMat", (0.2, 0.4, 0.8)))
    cube_prim.AddTranslateOp().Set(Gf.Vec3d(1.5, 0.5, 0.0))
    tris += triangle_count(cube[1])

    # Sphere of radius 0.6 whose bottom pole vertex touches y = 0.
    sphere = uv_sphere_y(0.6, 32, 16)
    sph = make_mesh(stage, "/World/Sphere", sphere, False,
                    make_material(stage, "/World/Looks/SphereMat", (0.85, 0.6, 0.2)))
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
    pl = make_mesh(stage, "/World/Plank", plank, False,
                   make_material(stage, "/World/Looks/PlankMat", (0.6, 0.45, 0.3)))
    pl.AddTranslateOp().Set(Gf.Vec3d(p0x, 0.0, 0.0))
    pl.AddRotateZOp(UsdGeom.XformOp.PrecisionDouble).Set(math.degrees(alpha))
    tris += triangle_count(plank[1])

    # RectLight above; rotateX(-90) maps local -Z to world -Y (down).
    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(1.5)
    light.CreateHeightAttr(1.5)
    light.CreateIntensityAttr(10.0)
    light.AddTranslateOp().Set(Gf.Vec3d(1.0, 5.0, 1.0))
    light.AddRotateXOp().Set(-90.0)
    check_points_down(light.GetPrim(), (0, -1, 0), 0.999)

    make_camera(stage, (0.5, 4.0, 7.0), (0.3, 0.4, 0.3), (0.0, 1.0, 0.0), clip=(0.1, 100.0))
    mark_casters(stage, ['/World/Cube', '/World/Sphere', '/World/Plank'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_multi_light(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "multi_light.usda")
    stage = new_stage(path, "Z")
    tris = 0

    def add(name: str, m: MeshData, color, double_sided=False):
        nonlocal tris
        mat = make_material(stage, "/World/Looks/%sMat" % name, color)
        make_mesh(stage, "/World/%s" % name, m, double_sided, mat)
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
    rect = UsdLux.RectLight.Define(stage, "/World/Lights/Rect")
    rect.CreateWidthAttr(1.2)
    rect.CreateHeightAttr(0.8)
    rect.CreateIntensityAttr(20.0)
    rect.AddTransformOp().Set(look_at_xform((-2.5, -1.0, 5.0), (-2.5, -1.5, 0.0), (0, 1, 0)))
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.9)

    disk = UsdLux.DiskLight.Define(stage, "/World/Lights/Disk")
    disk.CreateRadiusAttr(0.5)
    disk.CreateIntensityAttr(20.0)
    disk.AddTransformOp().Set(look_at_xform((2.5, -1.0, 4.5), (2.0, -2.5, 0.0), (0, 1, 0)))
    check_points_down(disk.GetPrim(), (0, 0, -1), 0.9)

    sphere = UsdLux.SphereLight.Define(stage, "/World/Lights/Sphere")
    sphere.CreateRadiusAttr(0.3)
    sphere.CreateIntensityAttr(30.0)
    sphere.AddTranslateOp().Set(Gf.Vec3d(-1.5, 2.5, 3.5))

    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateAngleAttr(2.0)
    sun.CreateIntensityAttr(2.0)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(35.0, 0.0, 30.0))
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)

    noshadow = UsdLux.SphereLight.Define(stage, "/World/Lights/NoShadow")
    noshadow.CreateRadiusAttr(0.2)
    noshadow.CreateIntensityAttr(10.0)
    noshadow.AddTranslateOp().Set(Gf.Vec3d(3.0, 2.0, 2.5))
    UsdLux.ShadowAPI.Apply(noshadow.GetPrim()).CreateShadowEnableAttr(False)

    dome = UsdLux.DomeLight.Define(stage, "/World/Lights/Dome")
    dome.CreateIntensityAttr(0.2)

    make_camera(stage, (0.0, -11.0, 9.0), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def write_checker_png(path: str, size: int = 64, cells: int = 8) -> None:
    """RGBA checker: cell (row, col) of the *image* (row 0 = top) is opaque
    (alpha 255, orange) when (row + col) is even, else transparent (alpha 0)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    cell = size // cells
    yy, xx = np.mgrid[0:size, 0:size]
    opaque = ((yy // cell + xx // cell) % 2) == 0
    img = np.zeros((size, size, 4), dtype=np.uint8)
    img[opaque] = (230, 120, 40, 255)
    img[~opaque] = (0, 0, 0, 0)
    Image.fromarray(img, "RGBA").save(path, format="PNG", optimize=False)


def scene_cutout(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "cutout.usda")
    write_checker_png(os.path.join(out_dir, "textures", "checker_alpha.png"))
    stage = new_stage(path, "Z")
    tris = 0

    ground = quad_mesh([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)])
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris += triangle_count(ground[1])

    # Cutout material: opacity <- texture alpha, opacityThreshold 0.5.
    UsdGeom.Scope.Define(stage, "/World/Looks")
    mat = UsdShade.Material.Define(stage, "/World/Looks/FenceMat")
    surf = UsdShade.Shader.Define(stage, "/World/Looks/FenceMat/PreviewSurface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.9, 0.47, 0.16))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.7)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    reader = UsdShade.Shader.Define(stage, "/World/Looks/FenceMat/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    tex = UsdShade.Shader.Define(stage, "/World/Looks/FenceMat/AlphaTexture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("textures/checker_alpha.png"))
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.ConnectableAPI(), "result")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
        tex.ConnectableAPI(), "a")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")

    fence = quad_mesh([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)])
    fmesh = make_mesh(stage, "/World/Fence", fence, True, mat)
    st = UsdGeom.PrimvarsAPI(fmesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set(Vt.Vec2fArray([Gf.Vec2f(0, 0), Gf.Vec2f(1, 0), Gf.Vec2f(1, 1), Gf.Vec2f(0, 1)]))
    tris += triangle_count(fence[1])

    leaf = box_mesh((2.0, -0.5, 0.6), (3.0, 0.5, 1.2))
    make_mesh(stage, "/World/Leaf", leaf, False,
              make_material(stage, "/World/Looks/LeafMat", (0.3, 0.6, 0.25)))
    tris += triangle_count(leaf[1])

    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(0.5)
    light.CreateHeightAttr(0.5)
    light.CreateIntensityAttr(20.0)
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 4.0))
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    make_camera(stage, (0.5, -2.5, 8.0), (0.5, 0.0, 0.0), (0.0, 0.0, 1.0), aspect="1:1",
                clip=(0.1, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# --- city -------------------------------------------------------------------


def facade_wall(origin, u, count: int, floors: int, cell_w: float, floor_h: float,
                win_u: Tuple[float, float], win_v: Tuple[float, float],
                inset: float) -> MeshData:
    """Wall of count x floors cells, each with a recessed window.

    The wall spans origin + [0, count*cell_w] * u + [0, floors*floor_h] * Z and
    faces n = u x Z.  Each cell: 4 frame quads around the window opening,
    4 reveal quads and 1 recessed back quad (9 quads = 18 triangles).
    """
    o = np.asarray(origin, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    v = np.array([0.0, 0.0, 1.0])
    n = np.cross(u, v)
    pts: List[np.ndarray] = []
    idx: List[int] = []
    for j in range(floors):
        for i in range(count):
            base = len(pts)

            def P(a: float, b: float, d: float = 0.0) -> np.ndarray:
                return o + a * u + b * v - d * n

            x0, x1 = i * cell_w, (i + 1) * cell_w
            y0, y1 = j * floor_h, (j + 1) * floor_h
            wx0, wx1 = x0 + win_u[0] * cell_w, x0 + win_u[1] * cell_w
            wy0, wy1 = y0 + win_v[0] * floor_h, y0 + win_v[1] * floor_h
            pts += [P(x0, y0), P(x1, y0), P(x1, y1), P(x0, y1),                  # O 0..3
                    P(wx0, wy0), P(wx1, wy0), P(wx1, wy1), P(wx0, wy1),          # I 4..7
                    P(wx0, wy0, inset), P(wx1, wy0, inset),
                    P(wx1, wy1, inset), P(wx0, wy1, inset)]                      # B 8..11
            for k in range(4):
                k1 = (k + 1) % 4
                idx += [base + k, base + k1, base + 4 + k1, base + 4 + k]        # frame
                idx += [base + 4 + k, base + 4 + k1, base + 8 + k1, base + 8 + k]  # reveal
            idx += [base + 8, base + 9, base + 10, base + 11]                    # back
    return np.asarray(pts), [4] * (len(idx) // 4), idx


def building_mesh(cx: int, cy: int, floors: int, cell_w: float, floor_h: float,
                  win_u, win_v, inset: float, roof_box: Tuple[float, float, float]) -> MeshData:
    W, D, H = cx * cell_w, cy * cell_w, floors * floor_h
    walls = [
        facade_wall((-W / 2, -D / 2, 0), (1, 0, 0), cx, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((W / 2, -D / 2, 0), (0, 1, 0), cy, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((W / 2, D / 2, 0), (-1, 0, 0), cx, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((-W / 2, D / 2, 0), (0, -1, 0), cy, floors, cell_w, floor_h, win_u, win_v, inset),
    ]
    roof = quad_mesh([(-W / 2, -D / 2, H), (W / 2, -D / 2, H), (W / 2, D / 2, H), (-W / 2, D / 2, H)])
    rw, rd, rh = roof_box
    pent = box_mesh((-rw / 2, -rd / 2, H), (rw / 2, rd / 2, H + rh))
    # drop the penthouse bottom face (first quad, -Z): it lies on the roof
    pent = (pent[0], pent[1][1:], pent[2][4:])
    return weld(merge_meshes(walls + [roof, pent]))


CITY_PROTOTYPES = [
    # (cells x, cells y, floors, cell width, floor height)
    (3, 3, 10, 3.0, 3.5),
    (4, 4, 10, 3.0, 3.5),
    (4, 3, 12, 3.0, 3.5),
    (5, 3, 10, 3.0, 3.5),
    (5, 5, 8, 3.0, 4.0),
    (3, 2, 20, 3.0, 3.5),
    (6, 4, 8, 3.0, 3.0),
    (4, 4, 13, 3.0, 3.5),
    (6, 3, 7, 3.0, 4.0),
    (3, 3, 16, 3.0, 3.5),
    (5, 4, 9, 3.0, 3.5),
    (2, 2, 25, 3.5, 3.5),
]


def scene_city(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "city.usdc")
    stage = new_stage(path, "Z")
    rng = np.random.default_rng(20240611)

    # Prototypes: a class root (abstract, never rendered itself).
    proto_root = stage.CreateClassPrim("/Prototypes")
    proto_root.SetTypeName("Scope")
    proto_tris: List[int] = []
    for k, (cx, cy, fl, cw, fh) in enumerate(CITY_PROTOTYPES):
        ppath = "/Prototypes/Building%02d" % k
        stage.DefinePrim(ppath, "Xform")
        win_u = (0.2 + 0.05 * (k % 3), 0.8 - 0.05 * (k % 3))
        win_v = (0.25, 0.8 - 0.05 * (k % 2))
        inset = 0.25 + 0.05 * (k % 4)
        roof_box = (cx * cw * 0.4, cy * cw * 0.4, 2.0 + (k % 3))
        m = building_mesh(cx, cy, fl, cw, fh, win_u, win_v, inset, roof_box)
        grey = 0.45 + 0.04 * (k % 6)
        tint = ((k * 37) % 11) / 100.0
        mat = make_material(stage, ppath + "/Looks/Facade",
                            (grey + tint, grey, grey - tint * 0.5))
        make_mesh(stage, ppath + "/Mesh", m, False, mat)
        proto_tris.append(triangle_count(m[1]))

    ground = quad_mesh([(-400, -400, 0), (400, -400, 0), (400, 400, 0), (-400, 400, 0)])
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.35, 0.35, 0.33)))
    total = triangle_count(ground[1])

    stage.DefinePrim("/World/City", "Xform")
    n_side, spacing = 19, 32.0
    n_inst = 0
    for r in range(n_side):
        for c in range(n_side):
            skip = rng.random() < 0.06
            proto = int(rng.integers(0, len(CITY_PROTOTYPES)))
            rot = 90.0 * int(rng.integers(0, 4))
            hscale = float(np.round(rng.uniform(0.7, 1.5), 3))
            jitter = np.round(rng.uniform(-2.0, 2.0, size=2), 3)
            if skip:  # open plaza
                continue
            x = (c - (n_side - 1) / 2) * spacing + float(jitter[0])
            y = (r - (n_side - 1) / 2) * spacing + float(jitter[1])
            inst = UsdGeom.Xform.Define(stage, "/World/City/B_%02d_%02d" % (r, c))
            prim = inst.GetPrim()
            prim.GetReferences().AddInternalReference(
                Sdf.Path("/Prototypes/Building%02d" % proto))
            prim.SetInstanceable(True)
            inst.AddTranslateOp().Set(Gf.Vec3d(x, y, 0.0))
            inst.AddRotateZOp().Set(rot)
            inst.AddScaleOp().Set(Gf.Vec3f(1.0, 1.0, hscale))
            total += proto_tris[proto]
            n_inst += 1

    stage.DefinePrim("/World/Lights", "Xform")
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateAngleAttr(1.0)
    sun.CreateIntensityAttr(3.0)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(40.0, 0.0, 35.0))
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)

    rect = UsdLux.RectLight.Define(stage, "/World/Lights/Rect")
    rect.CreateWidthAttr(4.0)
    rect.CreateHeightAttr(4.0)
    rect.CreateIntensityAttr(5000.0)
    rect.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 250.0))
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.999)

    make_camera(stage, (-450.0, -540.0, 330.0), (15.0, 25.0, 0.0), (0.0, 0.0, 1.0),
                focal=26.0, clip=(1.0, 5000.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": total, "instances": n_inst,
            "prototype_triangles": proto_tris}


# --- penumbra ramp ----------------------------------------------------------

# (x, z) of the plate centres: penumbra width on the ground grows with z.
PENUMBRA_PLATES = [(-6.0, 0.25), (-3.0, 0.75), (0.0, 1.5), (3.0, 2.5), (6.0, 3.5)]
PENUMBRA_LIGHT_Z = 6.0
PENUMBRA_LIGHT_SIZE = 1.5
PENUMBRA_PLATE_SIZE = 0.8
PENUMBRA_PLATE_THICK = 0.05


def scene_penumbra_ramp(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "penumbra_ramp.usda")
    stage = new_stage(path, "Z")
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
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.8)))
    tris = triangle_count(ground[1])

    plate_mat = make_material(stage, "/World/Looks/PlateMat", (0.8, 0.3, 0.2))
    stage.DefinePrim("/World/Plates", "Xform")
    for k, (x, z) in enumerate(PENUMBRA_PLATES):
        plate = box_mesh((x - hs, -hs, z - ht), (x + hs, hs, z + ht))
        check_closed(plate, "Plate%d" % k)
        make_mesh(stage, "/World/Plates/Plate%d" % k, plate, False, plate_mat)
        tris += triangle_count(plate[1])

    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(s)
    light.CreateHeightAttr(s)
    light.CreateIntensityAttr(10.0)
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, L))  # identity rotation: emits -Z
    check_points_down(light.GetPrim(), (0, 0, -1), 0.999)

    make_camera(stage, (5.0, -15.0, 12.0), (5.0, 0.0, 0.6), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    mark_casters(stage, ['/World/Plates'])
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# --- lightmapped bridge (Salzman, "Simpler Soft Shadow Mapping") -------------

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


def humanoid_parts() -> List[Tuple[str, MeshData]]:
    """Boxes of a ~1.8 tall figure facing +X, feet on z = 0, centred on x = y = 0."""
    return [
        ("LegLeft", box_mesh((-0.09, 0.03, 0.0), (0.09, 0.19, 0.85))),
        ("LegRight", box_mesh((-0.09, -0.19, 0.0), (0.09, -0.03, 0.85))),
        ("Torso", box_mesh((-0.12, -0.22, 0.85), (0.12, 0.22, 1.47))),
        ("ArmLeft", box_mesh((-0.07, 0.23, 0.8), (0.07, 0.33, 1.44))),
        ("ArmRight", box_mesh((-0.07, -0.33, 0.8), (0.07, -0.23, 1.44))),
        ("Head", box_mesh((-0.11, -0.11, 1.5), (0.11, 0.11, 1.8))),
    ]


def scene_lightmapped_bridge(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "lightmapped_bridge.usda")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    f0, f1 = BRIDGE_FRAMES
    stage.SetStartTimeCode(f0)
    stage.SetEndTimeCode(f1)
    stage.SetTimeCodesPerSecond(24.0)
    tris = 0

    # Lights first: the bake reads their world transforms.
    stage.DefinePrim("/World/Lights", "Xform")
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateAngleAttr(1.5)
    sun.CreateIntensityAttr(1.0)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(18.0, 0.0, 117.0))
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
        mesh = make_mesh(stage, "/World/Static/%s" % name, m, False,
                         make_material(stage, "/World/Looks/%sMat" % name, color))
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
    body_mat = make_material(stage, "/World/Looks/CharacterMat", body_color)
    for name, m in humanoid_parts():
        check_closed(m, name)
        mesh = make_mesh(stage, "/World/Dynamic/Character/%s" % name, m, False, body_mat)
        set_display_color(mesh, body_color)
        tris += triangle_count(m[1])

    ball_r, ball_color = 0.4, (0.85, 0.2, 0.2)
    ball = z_sphere(ball_r, 24, 12)
    check_closed(ball, "Ball")
    bmesh = make_mesh(stage, "/World/Dynamic/Ball", ball, False,
                      make_material(stage, "/World/Looks/BallMat", ball_color))
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

    make_camera(stage, (-2.5, -10.5, 4.6), (0.0, 0.0, 1.9), (0.0, 0.0, 1.0), clip=(0.1, 200.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# --- irregular z-buffer scenes (Galoppo, "Eye-View Pixel Anti-Aliasing for Irregular
#     Shadow Mapping", figs. 1.6.4 and 1.6.11): hard shadows of thin geometry --------


def point_light(stage: Usd.Stage, path: str, position: Sequence[float],
                intensity: float) -> UsdLux.SphereLight:
    """A SphereLight of radius 0 with treatAsPoint = true (hard shadows)."""
    light = UsdLux.SphereLight.Define(stage, path)
    light.CreateRadiusAttr(0.0)
    light.CreateTreatAsPointAttr(True)
    light.CreateIntensityAttr(float(intensity))
    light.AddTranslateOp().Set(Gf.Vec3d(*map(float, position)))
    return light


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


def tower_parts() -> Dict[str, List[MeshData]]:
    """Bars of the lattice tower by group: Legs, Rings, Braces, Arms."""
    dz = TOWER_HEIGHT / TOWER_LEVELS
    zs = [dz * i for i in range(TOWER_LEVELS + 1)]
    legs: List[MeshData] = []
    rings: List[MeshData] = []
    braces: List[MeshData] = []
    arms: List[MeshData] = []
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


def scene_tower(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "tower.usda")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    g = TOWER_GROUND_HALF
    ground = quad_mesh([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)])
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.8, 0.8, 0.78)))
    tris = triangle_count(ground[1])

    steel = make_material(stage, "/World/Looks/SteelMat", (0.45, 0.47, 0.5), roughness=0.5)
    stage.DefinePrim("/World/Tower", "Xform")
    counts = {}
    for name, bars in tower_parts().items():
        m = merge_meshes(bars)  # bars overlap at the joints; each is closed on its own
        check_closed(m, "Tower/" + name)
        make_mesh(stage, "/World/Tower/" + name, m, False, steel)
        counts[name] = len(bars)
        tris += triangle_count(m[1])

    point_light(stage, "/World/Light", TOWER_LIGHT, 60.0)
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
    make_camera(stage, (-7.5, -1.5, 6.5), (-1.5, 1.5, 0.9), (0.0, 0.0, 1.0), clip=(0.1, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


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


def scene_tunnel_fan(out_dir: str) -> Dict[str, object]:
    path = os.path.join(out_dir, "tunnel_fan.usda")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    L, h = TUNNEL_LENGTH, TUNNEL_HALF
    nl, nw = int(round(L / TUNNEL_CELL)), int(round(2 * h / TUNNEL_CELL))
    tris = 0

    # Single-sided surfaces, wound so that their normals face into the tunnel.
    stage.DefinePrim("/World/Tunnel", "Xform")
    floor_mat = make_material(stage, "/World/Looks/FloorMat", (0.75, 0.73, 0.7))
    wall_mat = make_material(stage, "/World/Looks/WallMat", (0.7, 0.72, 0.78))
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
        make_mesh(stage, "/World/Tunnel/" + name, m, False, mat)
        tris += triangle_count(m[1])

    stage.DefinePrim("/World/Fan", "Xform")
    fan_mat = make_material(stage, "/World/Looks/FanMat", (0.25, 0.3, 0.35), roughness=0.4)
    hr, hl, hn = FAN_HUB
    hub = prism_z(hn, hr, -0.5 * hl, 0.5 * hl)
    # (x, y, z) -> (z, x, y) is a rotation (a cyclic permutation): the prism's axis becomes X
    hub = translate_mesh((hub[0][:, [2, 0, 1]], hub[1], hub[2]), (FAN_X, 0.0, h))
    check_closed(hub, "Fan/Hub")
    make_mesh(stage, "/World/Fan/Hub", hub, False, fan_mat)
    tris += triangle_count(hub[1])
    blades = merge_meshes([fan_blade(k) for k in range(FAN_BLADES)])
    check_closed(blades, "Fan/Blades")
    make_mesh(stage, "/World/Fan/Blades", blades, False, fan_mat)
    tris += triangle_count(blades[1])

    point_light(stage, "/World/Light", TUNNEL_LIGHT, 60.0)
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

    make_camera(stage, (0.5, 0.3, 1.25), (12.0, -0.15, 0.9), (0.0, 0.0, 1.0), clip=(0.05, 100.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


# --- forest -----------------------------------------------------------------

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
               size: float) -> Tuple[np.ndarray, List[int], List[int], np.ndarray]:
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


def make_cutout_material(stage: Usd.Stage, path: str, color: Sequence[float], texture: str,
                         threshold: float = 0.5) -> UsdShade.Material:
    """A UsdPreviewSurface whose opacity is a UsdUVTexture's alpha (st from the `st` primvar) with
    `opacityThreshold`: a cutout, as in cutout.usda."""
    mat = UsdShade.Material.Define(stage, path)
    surf = UsdShade.Shader.Define(stage, path + "/PreviewSurface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.7)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(float(threshold))
    reader = UsdShade.Shader.Define(stage, path + "/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    tex = UsdShade.Shader.Define(stage, path + "/AlphaTexture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture))
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(tex.ConnectableAPI(), "a")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def scene_forest(out_dir: str) -> Dict[str, object]:
    """About 10,000 trees placed by one PointInstancer (4 prototypes of ~5,500 triangles each,
    over 50M instanced triangles) on a 240 x 240 ground: scale for instanced geometry."""
    path = os.path.join(out_dir, "forest.usdc")
    write_checker_png(os.path.join(out_dir, "textures", "checker_alpha.png"))
    stage = new_stage(path, "Z")
    rng = np.random.default_rng(20250214)

    ground = grid_quad_mesh((-FOREST_HALF, -FOREST_HALF, 0.0), (2 * FOREST_HALF, 0.0, 0.0),
                            (0.0, 2 * FOREST_HALF, 0.0), 8, 8)
    make_mesh(stage, "/World/Ground", ground, False,
              make_material(stage, "/World/Looks/GroundMat", (0.36, 0.3, 0.22)))
    ground_tris = triangle_count(ground[1])

    pi = UsdGeom.PointInstancer.Define(stage, "/World/Forest")
    protos_root = "/World/Forest/Prototypes"
    UsdGeom.Scope.Define(stage, protos_root)
    bark = make_material(stage, "/World/Looks/Bark", (0.35, 0.25, 0.16))
    proto_paths, proto_tris = [], []
    for k, (name, tr, th, shape, zc, (rxy, rz), leaf, nleaf, cutout) in enumerate(FOREST_PROTOTYPES):
        root = "%s/%s" % (protos_root, name)
        xf = UsdGeom.Xform.Define(stage, root)
        if name == "Oak":  # a prototype with its own transform on its root
            xf.AddRotateZOp().Set(30.0)
            xf.AddScaleOp().Set(Gf.Vec3f(1.1, 1.1, 1.0))
        trunk = trunk_mesh(tr, th)
        make_mesh(stage, root + "/Trunk", trunk, False, bark)
        crown_parent = root
        if name == "Shrub":  # a nested child transform inside a prototype
            crown_parent = root + "/Crown"
            UsdGeom.Xform.Define(stage, crown_parent).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.2))
        pts, counts, idx, st = leaf_quads(rng, nleaf, shape, zc, rxy, rz, leaf)
        green = (0.18 + 0.05 * k, 0.42 - 0.03 * k, 0.16)
        if cutout:
            mat = make_cutout_material(stage, "/World/Looks/%sLeaves" % name, green, "textures/checker_alpha.png")
        else:
            mat = make_material(stage, "/World/Looks/%sLeaves" % name, green)
        lm = make_mesh(stage, crown_parent + "/Leaves", (pts, counts, idx), True, mat)
        pv = UsdGeom.PrimvarsAPI(lm).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
        pv.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(st, dtype=np.float32)))
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
    sun = UsdLux.DistantLight.Define(stage, "/World/Lights/Sun")
    sun.CreateAngleAttr(1.5)
    sun.CreateIntensityAttr(3.0)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(35.0, 0.0, 40.0))
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)
    rect = UsdLux.RectLight.Define(stage, "/World/Lights/Rect")
    rect.CreateWidthAttr(12.0)
    rect.CreateHeightAttr(12.0)
    rect.CreateIntensityAttr(4000.0)
    rect.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 90.0))
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.999)

    make_camera(stage, (-150.0, -170.0, 70.0), (10.0, 15.0, 0.0), (0.0, 0.0, 1.0),
                focal=24.0, clip=(0.5, 2000.0))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc",
                   "forest: %d trees (PointInstancer /World/Forest, %d invisibleIds) of %d prototypes "
                   "(%s triangles), %d instanced triangles; ground %gx%g"
                   % (int(shown.sum()), len(FOREST_INVISIBLE), len(FOREST_PROTOTYPES),
                      ", ".join(str(t) for t in proto_tris), inst_tris, 2 * FOREST_HALF, 2 * FOREST_HALF))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": ground_tris + inst_tris, "instances": int(shown.sum()),
            "prototype_triangles": proto_tris}


SCENES: Dict[str, Callable[[str], Dict[str, object]]] = {
    "box_plane": scene_box_plane,
    "contact": scene_contact,
    "multi_light": scene_multi_light,
    "cutout": scene_cutout,
    "city": scene_city,
    "penumbra_ramp": scene_penumbra_ramp,
    "lightmapped_bridge": scene_lightmapped_bridge,
    "tower": scene_tower,
    "tunnel_fan": scene_tunnel_fan,
    "forest": scene_forest,
}


def _organic(name: str) -> Callable[[str], dict[str, object]]:
    """Scene from organic.py, imported on first use (organic.py imports this module)."""

    def run(out_dir: str) -> dict[str, object]:
        here = os.path.dirname(os.path.abspath(__file__))
        if here not in sys.path:
            sys.path.insert(0, here)
        import organic

        return organic.ORGANIC_SCENES[name](out_dir)

    run.__name__ = "scene_" + name
    return run


for _name in ("ogre", "plants", "dinosaurs", "fig1_plant", "fig8_tree", "palm_dino"):
    SCENES[_name] = _organic(_name)


def _stsv(name: str) -> Callable[[str], dict[str, object]]:
    """Scene from stsv_scenes.py (Forest et al. 2009 analogs), imported on first use."""

    def run(out_dir: str) -> dict[str, object]:
        here = os.path.dirname(os.path.abspath(__file__))
        if here not in sys.path:
            sys.path.insert(0, here)
        import stsv_scenes

        return stsv_scenes.STSV_SCENES[name](out_dir)

    run.__name__ = "scene_" + name
    return run


for _name in ("fence_perforated", "fence_mesh", "hl2_like", "factory", "greece", "wedge_overlap"):
    SCENES[_name] = _stsv(_name)


def main(argv: Optional[Sequence[str]] = None) -> int:
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=here, help="output folder (default: this script's folder)")
    ap.add_argument("--only", nargs="+", metavar="NAME",
                    help="generate only these scenes: " + ", ".join(SCENES))
    args = ap.parse_args(argv)

    names = list(SCENES)
    if args.only:
        names = []
        for n in args.only:
            key = os.path.splitext(os.path.basename(n))[0]
            if key not in SCENES:
                ap.error("unknown scene %r (choose from %s)" % (n, ", ".join(SCENES)))
            if key not in names:
                names.append(key)
    out_dir = os.path.abspath(args.out)
    os.makedirs(out_dir, exist_ok=True)

    for name in names:
        info = SCENES[name](out_dir)
        extra = ""
        if "instances" in info:
            extra = "  (%d instances of %d prototypes)" % (
                info["instances"], len(info["prototype_triangles"]))
        print("%-18s %-40s %9d triangles%s" % (name, info["file"], info["triangles"], extra))
        if name == "city":
            print("city total triangle count: %d" % info["triangles"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
