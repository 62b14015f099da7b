"""The scene on a Warp device: BVH, triangles, cutout materials and their alpha textures.

:func:`upload_scene` builds a :class:`DeviceScene`: the soup's ``wp.Mesh``, its per-triangle
:class:`~wsoft.scene.surfaces.Surfaces` (and the instances', :mod:`wsoft.scene.instancing`),
albedo and baked light. :func:`view_surfaces`, :func:`face_surfaces` and :func:`shadow_surfaces`
give the surfaces one light view or one light's shadow rays meet.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wsoft.errors import SceneError
from wsoft.scene.instancing import empty_instances, upload_instances
from wsoft.scene.surfaces import CULL_SKIP, Surfaces, surfaces_with_cull
from wsoft.scene.types import Scene


@dataclass
class DeviceScene:
    """Arrays of one scene on one device (built by the ``upload_scene`` pass).

    Per-triangle arrays span the *combined* triangle space of :mod:`wsoft.scene.instancing`: the
    soup's triangles (``mesh``, ``points``, ``indices``), then the prototypes' of an instanced scene
    (``instances``); ``tri_total`` counts both."""

    device: str
    mesh: wp.Mesh
    points: wp.array
    indices: wp.array  # flat [3T] int32 (the soup's triangles)
    cutouts: Surfaces
    has_cutouts: int
    culled_closed: int  # triangles of closed surfaces whose far-facing side the light view may skip
    cull_host: np.ndarray  # [T] int32, the cull flags on the host (a view may turn some prims' off)
    tri_prim: np.ndarray  # [T] int32 prim of each triangle (host)
    closed_lo: np.ndarray  # [P, 3] bounds of each prim's culled triangles (+inf / -inf: none)
    closed_hi: np.ndarray
    tri_albedo: wp.array  # [T] vec3
    tri_baked: wp.array  # [3T] vec3 baked light per corner (primvars:wsoft:bakedLight)
    tri_has_baked: wp.array  # [T] int32
    diagonal: float
    lo: np.ndarray
    hi: np.ndarray
    tri_total: int = 0  # triangles in the combined space (soup + prototypes)
    instances: object = None  # wsoft.scene.instancing.DeviceInstances, or None
    inst: object = None  # its InstancesGPU (an empty one when the scene has no instances): kernels take it
    packed: tuple | None = None  # (PackedBVH or None, its stats), built by wsoft.reference.packets.packed_bvh on first use
    linked: dict = field(default_factory=dict)  # excluded prims -> (Surfaces, has_cutouts), built by shadow_surfaces
    occluders: dict = field(default_factory=dict)  # excluded prims -> Occluders, built by wsoft.scene.rays.occluders

    def arrays(self) -> dict[str, wp.array]:
        c = self.cutouts
        out = {
            "points": self.points,
            "indices": self.indices,
            "tri_albedo": self.tri_albedo,
            "tri_cut": c.tri_cut,
            "tri_uv": c.tri_uv,
            "tex_data": c.tex_data,
        }
        if self.instances is not None:
            out["proto_points"] = self.instances.proto_points
            out["proto_indices"] = self.instances.proto_indices
        return out


def _combined(scene: Scene) -> dict[str, np.ndarray]:
    """The per-triangle fields over the combined space (the soup, then every prototype's triangles;
    a soup with no triangle beside instances gets one zero-area stand-in, culled from every map)."""
    parts = [dict(material=scene.tri_material, uv=scene.tri_uv, ds=scene.tri_double_sided,
                  closed=np.zeros(scene.triangle_count, np.int8) if scene.tri_closed is None else scene.tri_closed,
                  prim=scene.tri_prim, skip=np.zeros(scene.triangle_count, bool),
                  baked=None if scene.tri_baked is None else scene.tri_baked)]
    if scene.triangle_count == 0:
        parts = [dict(material=np.zeros(1, np.int32), uv=np.zeros((1, 3, 2), np.float32), ds=np.ones(1, bool), closed=np.zeros(1, np.int8),
                      prim=np.full(1, -1, np.int32), skip=np.ones(1, bool), baked=None)]
    nsoup = max(scene.triangle_count, 1)
    if scene.instanced:
        for p in scene.instances.prototypes:
            parts.append(dict(material=p.tri_material, uv=p.tri_uv, ds=p.tri_double_sided, closed=p.tri_closed, prim=p.tri_prim,
                              skip=np.zeros(p.triangle_count, bool), baked=None))
    out = {k: np.concatenate([np.asarray(q[k]) for q in parts]) for k in ("material", "uv", "ds", "closed", "prim", "skip")}
    total = len(out["prim"])
    baked = np.full((total, 3, 3), np.nan, np.float32)
    if parts[0]["baked"] is not None and scene.triangle_count:
        baked[: scene.triangle_count] = parts[0]["baked"]
    out["baked"] = baked
    out["soup"] = nsoup
    return out


def upload_scene(scene: Scene, device: str) -> DeviceScene:
    """Copy the scene's triangles, cutouts and textures to ``device`` and build a BVH (and, for an
    instanced scene, the prototypes' BVHs and the top level over the instances,
    :mod:`wsoft.scene.instancing`)."""
    if scene.triangle_count == 0 and not scene.instanced:
        raise SceneError("the stage has no visible mesh triangles", file=scene.path)

    comb = _combined(scene)
    nsoup = int(comb["soup"])
    if scene.triangle_count:
        soup_pts, soup_tri = scene.points.astype(np.float32), scene.triangles.reshape(-1).astype(np.int32)
    else:  # everything is instanced: a zero-area stand-in that no ray hits
        soup_pts, soup_tri = np.zeros((3, 3), np.float32), np.arange(3, dtype=np.int32)
    pts = wp.array(soup_pts, dtype=wp.vec3, device=device)
    idx = wp.array(soup_tri, dtype=wp.int32, device=device)
    mesh = wp.Mesh(points=pts, indices=idx)
    total = len(comb["prim"])

    cut_ids = {}
    for i, m in enumerate(scene.materials):
        if m.is_cutout:
            cut_ids[i] = len(cut_ids)
    lut = np.full(max(len(scene.materials), 1), -1, np.int32)
    for i, c in cut_ids.items():
        lut[i] = c
    tri_cut = lut[comb["material"]]
    cut_mats = [scene.materials[i] for i in cut_ids]
    tex_offsets, off = [], 0
    for t in scene.textures:
        tex_offsets.append(off)
        off += t.data.size
    tex_data = np.concatenate([t.data.reshape(-1) for t in scene.textures]) if scene.textures else np.zeros(1, np.float32)

    def arr(a, dtype):
        a = np.asarray(a)
        if a.size == 0:
            a = np.zeros(1, dtype=np.int32 if dtype == wp.int32 else np.float32)
        return wp.array(a, dtype=dtype, device=device)

    cut = Surfaces()
    cut.tri_cut = arr(tri_cut.astype(np.int32), wp.int32)
    cut.double_sided = arr(comb["ds"].astype(np.int32), wp.int32)
    cull = comb["closed"].astype(np.int32)
    # a cutout lets the inside of a closed surface be seen: no culling for prims that have cutouts
    if np.any(tri_cut >= 0):
        cut_prims = np.unique(comb["prim"][tri_cut >= 0])
        cull[np.isin(comb["prim"], cut_prims)] = 0
    cull[comb["skip"]] = int(CULL_SKIP)
    cut.cull = arr(cull, wp.int32)
    cut.tri_uv = wp.array(comb["uv"].reshape(-1, 2).astype(np.float32), dtype=wp.vec2, device=device)
    cut.threshold = arr([m.opacity_threshold for m in cut_mats], wp.float32)
    cut.opacity = arr([m.opacity for m in cut_mats], wp.float32)
    cut.tex = arr([m.texture for m in cut_mats], wp.int32)
    cut.tex_offset = arr(tex_offsets, wp.int32)
    cut.tex_w = arr([t.data.shape[1] for t in scene.textures], wp.int32)
    cut.tex_h = arr([t.data.shape[0] for t in scene.textures], wp.int32)
    cut.tex_wrap_s = arr([t.wrap_s for t in scene.textures], wp.int32)
    cut.tex_wrap_t = arr([t.wrap_t for t in scene.textures], wp.int32)
    cut.tex_border = arr([t.border for t in scene.textures], wp.float32)
    cut.tex_data = wp.array(tex_data.astype(np.float32), dtype=wp.float32, device=device)
    albedo = np.array([m.albedo for m in scene.materials], np.float32)[comb["material"]]
    baked = comb["baked"]
    has_baked = np.isfinite(baked[:, 0, 0]).astype(np.int32)
    lo, hi = scene.bounds
    closed_lo, closed_hi = _closed_bounds(scene, cull[: scene.triangle_count])
    inst = upload_instances(scene.instances, nsoup, device) if scene.instanced else None
    return DeviceScene(
        device=device,
        mesh=mesh,
        points=pts,
        indices=idx,
        cutouts=cut,
        has_cutouts=int(bool(cut_ids) and bool(np.any(tri_cut >= 0))),
        culled_closed=int(np.count_nonzero((cull != 0) & (cull != int(CULL_SKIP)))),
        cull_host=cull,
        tri_prim=np.asarray(comb["prim"], np.int32),
        closed_lo=closed_lo,
        closed_hi=closed_hi,
        tri_albedo=wp.array(albedo, dtype=wp.vec3, device=device),
        tri_baked=wp.array(np.nan_to_num(baked).reshape(-1, 3), dtype=wp.vec3, device=device),
        tri_has_baked=wp.array(has_baked, dtype=wp.int32, device=device),
        diagonal=scene.diagonal,
        lo=lo,
        hi=hi,
        tri_total=total,
        instances=inst,
        inst=inst.gpu if inst is not None else empty_instances(device),
    )


def _closed_bounds(scene: Scene, cull: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per prim, the bounds of its triangles whose far side the light view may skip (+inf/-inf: none)."""
    n = max(len(scene.prims), int(scene.tri_prim.max()) + 1 if scene.triangle_count else 0, 1)
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    sel = np.flatnonzero((cull != 0) & (cull != int(CULL_SKIP)))
    if sel.size:
        pts = scene.points[scene.triangles[sel]].astype(np.float64)  # [k, 3, 3]
        prims = scene.tri_prim[sel]
        np.minimum.at(lo, prims, pts.min(axis=1))
        np.maximum.at(hi, prims, pts.max(axis=1))
    return lo, hi


def view_cull(ds: "DeviceScene", origin: np.ndarray | None) -> np.ndarray | None:
    """The cull flags (host, [T]) of a view from ``origin`` (None: orthographic, from infinitely
    far), or None where they are the scene's own: skipping the far faces of a closed surface is exact
    only when the view's origin lies outside it, so prims whose culled triangles' bounds hold the
    origin keep every face (flag 0: open, for this view)."""
    if origin is None or ds.culled_closed == 0:
        return None
    o = np.asarray(origin, np.float64)
    pad = 1e-6 * max(ds.diagonal, 1e-12)
    inside = np.flatnonzero(np.all((ds.closed_lo - pad <= o) & (o <= ds.closed_hi + pad), axis=1))
    if inside.size == 0:
        return None
    cull = ds.cull_host.copy()
    cull[np.isin(ds.tri_prim, inside)] = 0
    return cull


def view_surfaces(ds: "DeviceScene", origin: np.ndarray | None) -> Surfaces:
    """The scene's surfaces for a view from ``origin`` (:func:`view_cull`)."""
    cull = view_cull(ds, origin)
    if cull is None:
        return ds.cutouts
    return surfaces_with_cull(ds.cutouts, wp.array(cull, dtype=wp.int32, device=ds.device))


def face_surfaces(ds: "DeviceScene", origin: np.ndarray | None, faces: str) -> Surfaces:
    """The scene's surfaces for a view from ``origin`` reduced to ``faces``: ``back`` — the faces of
    closed surfaces turned away from the view (every ray that crosses a closed surface leaves it
    through one), ``open`` — every face of the surfaces that are not closed for this view."""
    cull = view_cull(ds, origin)
    cull = ds.cull_host if cull is None else cull
    skip = cull == int(CULL_SKIP)
    if faces == "back":
        flags = np.where(skip, int(CULL_SKIP), np.where(cull != 0, -cull, int(CULL_SKIP)))
    elif faces == "open":
        flags = np.where(cull != 0, int(CULL_SKIP), 0)
    else:
        raise ValueError(f"faces {faces!r} is not back or open")
    return surfaces_with_cull(ds.cutouts, wp.array(flags.astype(np.int32), dtype=wp.int32, device=ds.device))


def shadow_surfaces(ds: DeviceScene, excluded_prims: tuple[int, ...]) -> tuple[Surfaces, int]:
    """The surfaces shadow rays of one light meet, and their ``has_cutouts`` flag: ``ds``'s own when
    ``excluded_prims`` is empty (every prim casts), else a copy in which the triangles of the
    excluded prims (a light's ``collection:shadowLink``) are a cutout with nothing present, so
    any-hit queries (:func:`~wsoft.scene.rays.unoccluded`, the packet traversal) continue past them as they do through
    a cutout's holes. Eye rays keep ``ds.cutouts``: excluded prims are still seen. Built once per
    set of prims on each device."""
    if not excluded_prims:
        return ds.cutouts, ds.has_cutouts
    key = tuple(excluded_prims)
    if key not in ds.linked:
        c = ds.cutouts
        n_cut = int(c.threshold.shape[0]) if int(np.count_nonzero(c.tri_cut.numpy() >= 0)) else 0  # real cutout entries
        tri_cut = c.tri_cut.numpy().copy()
        out = np.isin(ds.tri_prim, np.asarray(key, np.int32))
        tri_cut[out] = n_cut  # a new entry: opacity 0 below threshold 1 (never present)
        s = Surfaces()
        for name in Surfaces.vars:
            setattr(s, name, getattr(c, name))
        dev = ds.device
        s.tri_cut = wp.array(tri_cut.astype(np.int32), dtype=wp.int32, device=dev)
        s.threshold = wp.array(np.r_[c.threshold.numpy()[:n_cut], 1.0].astype(np.float32), dtype=wp.float32, device=dev)
        s.opacity = wp.array(np.r_[c.opacity.numpy()[:n_cut], 0.0].astype(np.float32), dtype=wp.float32, device=dev)
        s.tex = wp.array(np.r_[c.tex.numpy()[:n_cut], -1].astype(np.int32), dtype=wp.int32, device=dev)
        ds.linked[key] = (s, int(bool(out.any()) or bool(ds.has_cutouts)))
    return ds.linked[key]


def refit_scene(ds: DeviceScene, scene: Scene) -> DeviceScene:
    """``ds``, the device copy of a scene with ``scene``'s triangles, materials and textures, moved
    to ``scene``'s points: the points copied into its arrays and its BVH refitted (``wp.Mesh.refit``:
    the tree kept, its boxes recomputed), the bounds and per-prim culling boxes recomputed, and what
    was built from the old points (the packed BVH, shadow-link occluder meshes) dropped to be built
    again on first use. The previous points are overwritten: ``ds`` is the new scene's from then on.
    Not for a scene with instances (their placements live in the top level, built once)."""
    if scene.instanced or ds.instances is not None:
        raise ValueError("refit_scene does not move instances")
    if scene.triangle_count == 0 or len(scene.points) != ds.points.shape[0]:
        raise ValueError("refit_scene needs the same points and triangles")
    ds.points.assign(scene.points.astype(np.float32))
    ds.mesh.refit()
    lo, hi = scene.bounds
    closed_lo, closed_hi = _closed_bounds(scene, ds.cull_host[: scene.triangle_count])
    return dataclasses.replace(ds, closed_lo=closed_lo, closed_hi=closed_hi, diagonal=scene.diagonal, lo=lo, hi=hi, packed=None,
                               linked={}, occluders={})
