"""Instances on the device: prototypes once, a top-level BVH over the instances' world bounds.

Warp has no instance layer, so this is one: every prototype of a scene's
:class:`~wsoft.scene.types.Instances` is a ``wp.Mesh`` of its own (in the prototype's frame), and a
``wp.Bvh`` over the instances' world boxes (the *top level*) finds the instances a ray can meet.
A ray is carried into an instance's frame by the inverse of its affine transform without
normalising the direction, so the ray parameter ``t`` is the same in both frames: a query's
``max_t`` and hit distance need no conversion.

**Triangle indices.** A scene's triangles are numbered in one *combined* space: the soup's
triangles first (``0 .. T-1``, the flat mesh's own face indices), then every prototype's
(``T + g`` for the prototype triangle ``g``, prototypes one after another). Every per-triangle
array of the device scene (:class:`~wsoft.scene.surfaces.Surfaces`, albedo, baked light) spans the
combined space, so a G-buffer sample's ``prim`` and a cutout lookup mean the same whichever level
the hit came from. The soup of a scene whose geometry is all instanced holds one zero-area
triangle that no ray can hit and no map draws (its cull flag is ``CULL_SKIP``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.scene.offsets import coordinate_scale
from wsoft.scene.surfaces import Surfaces, nearest_blocker_from, nearest_from, occluded_from


@wp.struct
class InstancesGPU:
    """The instances of a device scene (``count = 0``: none; every array then holds one dummy)."""

    count: int
    tlas: wp.uint64  # wp.Bvh over the instances' world bounds (0 when count == 0)
    to_object: wp.array[wp.mat44]  # [I] world -> prototype frame
    proto: wp.array[wp.int32]  # [I] prototype of each instance
    proto_mesh: wp.array[wp.uint64]  # [P] each prototype's wp.Mesh
    proto_tri0: wp.array[wp.int32]  # [P] the combined index of each prototype's first triangle


@wp.func
def occluded_instances(inst: InstancesGPU, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float) -> bool:
    """Is the segment origin + t*dir (``dir`` unit length), t in (0, max_t), blocked by an instance?"""
    if inst.count == 0:
        return False
    q = wp.bvh_query_ray(inst.tlas, origin, dir)
    i = int(0)
    blocked = bool(False)
    while not blocked and wp.bvh_query_next(q, i, max_t):
        m = inst.to_object[i]
        p = inst.proto[i]
        o = wp.transform_point(m, origin)
        d = wp.transform_vector(m, dir)
        if occluded_from(inst.proto_mesh[p], inst.proto_tri0[p], cut, has_cutouts, o, d, max_t):
            blocked = True
    return blocked


@wp.func
def nearest_blocker_instances(inst: InstancesGPU, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float) -> float:
    """The distance along the segment origin + t*dir (``dir`` unit length), t in (0, max_t), to the
    nearest instance surface that blocks it (:func:`~wsoft.scene.surfaces.nearest_blocker_from` in
    each instance's frame, where ``t`` is the world's), or -1 when none does."""
    best = float(-1.0)
    if inst.count == 0:
        return best
    reach = max_t
    q = wp.bvh_query_ray(inst.tlas, origin, dir)
    i = int(0)
    while wp.bvh_query_next(q, i, reach):
        m = inst.to_object[i]
        p = inst.proto[i]
        t = nearest_blocker_from(inst.proto_mesh[p], inst.proto_tri0[p], cut, has_cutouts, wp.transform_point(m, origin),
                                 wp.transform_vector(m, dir), reach)
        if t >= 0.0:
            best = t
            reach = t
    return best


@wp.func
def nearest_instance_hit(inst: InstancesGPU, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float):
    """The nearest surface an eye ray meets among the instances within ``max_t``: (found 0/1, t,
    combined triangle, u, v, unit world normal of the triangle's front side, the world hit point
    from the triangle's corners, its rounding scale in the world: the larger of the point's
    largest coordinate and the triangle's :func:`~wsoft.scene.offsets.triangle_scale` carried by
    the instance's scale along the ray). As the flat eye ray does: alpha-tested through cutouts,
    back faces of single-sided meshes skipped. The front side and the normal need no care for
    mirroring: the ray's side of a prototype triangle is the same in both frames (dot(M d, M^-T n)
    = dot(d, n)), as is the flattened loader's, which flips a mirrored mesh's winding."""
    best = max_t
    found = int(0)
    face = int(-1)
    bu = float(0.0)
    bv = float(0.0)
    n = wp.vec3(0.0)
    pw = wp.vec3(0.0)
    scale = float(0.0)
    if inst.count == 0:
        return found, best, face, bu, bv, n, pw, scale
    q = wp.bvh_query_ray(inst.tlas, origin, dir)
    i = int(0)
    while wp.bvh_query_next(q, i, best):
        m = inst.to_object[i]
        p = inst.proto[i]
        mesh = inst.proto_mesh[p]
        tri0 = inst.proto_tri0[p]
        d = wp.transform_vector(m, dir)
        f, t, tri, u, v, nrm, po, so = nearest_from(mesh, tri0, cut, has_cutouts, wp.transform_point(m, origin), d, best, 0.0)
        if f == 1:
            best = t
            found = 1
            face = tri
            bu = u
            bv = v
            # a normal goes to world by the inverse transpose: (to_object)^T
            n = wp.normalize(wp.transform_vector(wp.transpose(m), nrm))
            pw = wp.transform_point(wp.inverse(m), po)
            scale = wp.max(coordinate_scale(pw), so / wp.max(wp.length(d), 1.0e-30))  # |d| = 1 / the instance's scale along the ray
    return found, best, face, bu, bv, n, pw, scale


@dataclass
class DeviceInstances:
    """The host side of :class:`InstancesGPU`: what keeps the Warp objects alive, and what the
    rasterizer needs (prototype points and indices, per prototype the instances that place it)."""

    gpu: InstancesGPU
    meshes: list  # wp.Mesh per prototype
    tlas: object  # wp.Bvh or None
    proto_points: wp.array  # [sum V] vec3, every prototype's points (prototype frames)
    proto_indices: wp.array  # [3 sum T] int32 into proto_points
    proto_first: np.ndarray  # [P] first prototype triangle (in proto_indices) of each prototype
    proto_ntri: np.ndarray  # [P]
    to_world: np.ndarray  # [I, 4, 4] float64
    mirrored: np.ndarray  # [I] bool
    proto: np.ndarray  # [I] int32
    lo: np.ndarray  # [I, 3] world bounds
    hi: np.ndarray
    tri_base: int  # combined index of the first prototype triangle (the soup's triangle count)

    @property
    def count(self) -> int:
        return int(self.proto.shape[0])

    def memory_bytes(self) -> int:
        """Bytes held on the device for instancing: prototypes' points, indices and BVHs (estimated
        as Warp lays them out: 2 nodes per triangle, 32 bytes each), instance arrays and the top level."""
        nv = int(self.proto_points.shape[0])
        nt = int(self.proto_indices.shape[0]) // 3
        ni = self.count
        return 12 * nv + 12 * nt + 64 * nt + ni * (64 + 4) + 64 * max(ni, 1)


def empty_instances(device: str) -> InstancesGPU:
    g = InstancesGPU()
    g.count = 0
    g.tlas = wp.uint64(0)
    eye = np.eye(4, dtype=np.float32)[None]
    g.to_object = wp.array(eye, dtype=wp.mat44, device=device)
    g.proto = wp.zeros(1, dtype=wp.int32, device=device)
    g.proto_mesh = wp.zeros(1, dtype=wp.uint64, device=device)
    g.proto_tri0 = wp.zeros(1, dtype=wp.int32, device=device)
    return g


def upload_instances(inst, tri_base: int, device: str) -> DeviceInstances:
    """``inst`` (:class:`~wsoft.scene.types.Instances`) on ``device``: a ``wp.Mesh`` per prototype, the
    instance transforms both ways, and the top-level BVH over the instances' world bounds (padded
    by a relative 1e-6 so that a flat instance's box keeps a thickness)."""
    protos = inst.prototypes
    ntri = np.array([p.triangle_count for p in protos], np.int64)
    first = np.concatenate([[0], np.cumsum(ntri)[:-1]]).astype(np.int64)
    meshes, pts_all, idx_all, voff = [], [], [], 0
    for p in protos:
        pts = np.ascontiguousarray(p.points, np.float32)
        tri = np.ascontiguousarray(p.triangles.reshape(-1), np.int32)
        wpts = wp.array(pts, dtype=wp.vec3, device=device)
        meshes.append(wp.Mesh(points=wpts, indices=wp.array(tri, dtype=wp.int32, device=device)))
        pts_all.append(pts)
        idx_all.append(tri + voff)
        voff += len(pts)
    xf = np.asarray(inst.xform, np.float64)
    inv = np.linalg.inv(xf)
    mirrored = np.linalg.det(xf[:, :3, :3]) < 0
    lo, hi = inst.world_bounds
    pad = 1e-6 * max(float(np.max(hi - lo)) if len(lo) else 1.0, 1e-12) + 1e-7 * np.maximum(np.abs(lo), np.abs(hi))
    lo_p, hi_p = (lo - pad).astype(np.float32), (hi + pad).astype(np.float32)
    tlas = wp.Bvh(wp.array(lo_p, dtype=wp.vec3, device=device), wp.array(hi_p, dtype=wp.vec3, device=device))
    g = InstancesGPU()
    g.count = int(inst.count)
    g.tlas = tlas.id
    g.to_object = wp.array(inv.astype(np.float32), dtype=wp.mat44, device=device)
    g.proto = wp.array(np.asarray(inst.proto, np.int32), dtype=wp.int32, device=device)
    g.proto_mesh = wp.array(np.array([m.id for m in meshes], np.uint64), dtype=wp.uint64, device=device)
    g.proto_tri0 = wp.array((tri_base + first).astype(np.int32), dtype=wp.int32, device=device)
    return DeviceInstances(
        gpu=g, meshes=meshes, tlas=tlas,
        proto_points=wp.array(np.concatenate(pts_all) if pts_all else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device),
        proto_indices=wp.array(np.concatenate(idx_all) if idx_all else np.zeros(3, np.int32), dtype=wp.int32, device=device),
        proto_first=first, proto_ntri=ntri, to_world=xf, mirrored=mirrored, proto=np.asarray(inst.proto, np.int32),
        lo=lo, hi=hi, tri_base=int(tri_base),
    )
