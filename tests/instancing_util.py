"""Test helpers: an instanced scene made from a flat one, and the same scene flattened in numpy."""
import numpy as np, math
from dataclasses import replace
from wsoft.scene.types import Prototype, Instances
from wsoft.scene.usd import load_scene

def rot(axis, ang):
    a = np.asarray(axis, float); a /= np.linalg.norm(a)
    c, s = math.cos(ang), math.sin(ang)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K

def xf(R=np.eye(3), t=(0, 0, 0), s=(1, 1, 1)):
    M = np.eye(4); M[:3, :3] = R @ np.diag(s); M[:3, 3] = t; return M

def split(scene, prim_names, transforms):
    """Instanced scene: the prims named (their triangles, world frame = prototype frame) become one
    prototype each, placed by `transforms` (list of (proto, 4x4)); the rest stays the soup.
    Returns (instanced, flat) scenes."""
    keep = np.ones(scene.triangle_count, bool)
    protos = []
    for name in prim_names:
        pi = [i for i, p in enumerate(scene.prims) if p.endswith(name)][0]
        m = scene.tri_prim == pi
        keep &= ~m
        used = np.unique(scene.triangles[m])
        remap = np.full(len(scene.points), -1); remap[used] = np.arange(len(used))
        protos.append(Prototype(path=name, points=scene.points[used], triangles=remap[scene.triangles[m]].astype(np.int32),
                                tri_prim=scene.tri_prim[m], tri_material=scene.tri_material[m], tri_uv=scene.tri_uv[m],
                                tri_double_sided=scene.tri_double_sided[m], tri_closed=scene.tri_closed[m], tri_face=scene.tri_face[m]))
    soup = scene.subset(keep)
    proto = np.array([p for p, _ in transforms], np.int32)
    X = np.array([M for _, M in transforms], np.float64)
    inst = Instances(prototypes=protos, proto=proto, xform=X, prim=np.zeros(len(proto), np.int32),
                     instance_id=np.arange(len(proto), dtype=np.int32), dynamic=np.zeros(len(proto), bool))
    inst_scene = replace(soup, instances=inst); inst_scene.changed()
    # flat: soup + transformed copies
    pts, tris, fields = [soup.points], [soup.triangles], {k: [getattr(soup, k)] for k in ("tri_prim", "tri_material", "tri_uv", "tri_double_sided", "tri_closed", "tri_face")}
    nv = len(soup.points)
    for p, M in transforms:
        P = protos[p]
        w = (P.points.astype(np.float64) @ M[:3, :3].T + M[:3, 3]).astype(np.float32)
        t = P.triangles.copy()
        uv = P.tri_uv
        closed = P.tri_closed
        if np.linalg.det(M[:3, :3]) < 0:
            t = t[:, [0, 2, 1]]; uv = uv[:, [0, 2, 1]]
        pts.append(w); tris.append(t + nv); nv += len(w)
        for k in fields:
            v = getattr(P, k)
            if k == "tri_uv": v = uv
            fields[k].append(v)
    flat = replace(soup, points=np.concatenate(pts), triangles=np.concatenate(tris).astype(np.int32),
                   **{k: np.concatenate(v) for k, v in fields.items()}, tri_dynamic=np.zeros(sum(len(t) for t in tris), bool), tri_baked=None)
    flat.changed()
    return inst_scene, flat
