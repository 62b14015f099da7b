"""The scene on a Warp device: BVH, triangles, cutout materials and their alpha textures.

Kernels take a :class:`Surfaces` struct and call :func:`surface_present` to alpha-test a
point on a triangle; scenes without cutouts pass ``has_cutouts = 0`` and never sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wsoft.scene.types import Scene


@wp.struct
class Surfaces:
    """Per-triangle surface data: cutouts (``tri_cut[t]`` is a cutout index or -1 = opaque),
    their alpha textures, and sidedness (``double_sided[t]``: 0 = back face culled in the eye view).
    Shadows are cast by both sides of every triangle; ``cull`` only lets the light-view
    rasterizer skip faces of closed surfaces that can never be the nearest (exact)."""

    tri_cut: wp.array[wp.int32]  # [T]
    double_sided: wp.array[wp.int32]  # [T]
    cull: wp.array[wp.int32]  # [T] light view: +1 skip faces turned away, -1 skip faces turned toward, 0 keep all
    tri_uv: wp.array[wp.vec2]  # [3T] texture coordinates per triangle corner
    threshold: wp.array[wp.float32]  # [C] opacityThreshold
    opacity: wp.array[wp.float32]  # [C] constant opacity (used when tex < 0)
    tex: wp.array[wp.int32]  # [C] texture index or -1
    tex_offset: wp.array[wp.int32]  # [X] start of each texture in tex_data
    tex_w: wp.array[wp.int32]
    tex_h: wp.array[wp.int32]
    tex_wrap_s: wp.array[wp.int32]
    tex_wrap_t: wp.array[wp.int32]
    tex_data: wp.array[wp.float32]  # all textures, rows bottom-up


@wp.func
def wrap_coord(i: int, n: int, mode: int) -> int:
    """Texel index under a UsdUVTexture wrap mode (0 repeat, 1 mirror, 2 clamp, 3 black: -1)."""
    if mode == 0:
        r = i % n
        if r < 0:
            r += n
        return r
    if mode == 1:
        p = 2 * n
        r = i % p
        if r < 0:
            r += p
        if r >= n:
            r = p - 1 - r
        return r
    if mode == 2:
        return wp.clamp(i, 0, n - 1)
    if i < 0 or i >= n:
        return -1
    return i


@wp.func
def texel_value(cut: Surfaces, t: int, x: int, y: int) -> float:
    w = cut.tex_w[t]
    h = cut.tex_h[t]
    xi = wrap_coord(x, w, cut.tex_wrap_s[t])
    yi = wrap_coord(y, h, cut.tex_wrap_t[t])
    if xi < 0 or yi < 0:
        return 0.0
    return cut.tex_data[cut.tex_offset[t] + yi * w + xi]


@wp.func
def sample_alpha(cut: Surfaces, t: int, st: wp.vec2) -> float:
    """Bilinear sample of texture ``t`` at ``st`` (st=(0,0) is the image's lower-left corner)."""
    fx = st[0] * float(cut.tex_w[t]) - 0.5
    fy = st[1] * float(cut.tex_h[t]) - 0.5
    x0 = int(wp.floor(fx))
    y0 = int(wp.floor(fy))
    ax = fx - float(x0)
    ay = fy - float(y0)
    a = texel_value(cut, t, x0, y0) * (1.0 - ax) + texel_value(cut, t, x0 + 1, y0) * ax
    b = texel_value(cut, t, x0, y0 + 1) * (1.0 - ax) + texel_value(cut, t, x0 + 1, y0 + 1) * ax
    return a * (1.0 - ay) + b * ay


@wp.func
def surface_present(cut: Surfaces, tri: int, w0: float, w1: float, w2: float) -> bool:
    """Alpha test at barycentric weights (w0, w1, w2) of triangle ``tri``'s corners."""
    c = cut.tri_cut[tri]
    if c < 0:
        return True
    t = cut.tex[c]
    alpha = cut.opacity[c]
    if t >= 0:
        st = cut.tri_uv[3 * tri] * w0 + cut.tri_uv[3 * tri + 1] * w1 + cut.tri_uv[3 * tri + 2] * w2
        alpha = sample_alpha(cut, t, st)
    return alpha >= cut.threshold[c]


@wp.func
def occluded_from(mesh: wp.uint64, tri0: int, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float) -> bool:
    """Is the segment origin + t*dir, t in (0, max_t), blocked by ``mesh`` (whose face ``f`` is the
    triangle ``tri0 + f`` of ``cut``: 0 for the soup, a prototype's first combined index for an
    instance, :mod:`wsoft.scene.instancing`)? Any-hit, alpha-tested through cutouts; 64 cutout layers
    crossed count as blocked."""
    if has_cutouts == 0:
        return wp.mesh_query_ray_anyhit(mesh, origin, dir, max_t)
    o = origin
    remaining = max_t
    blocked = bool(False)
    for _k in range(64):
        if remaining > 0.0 and not blocked:
            q = wp.mesh_query_ray(mesh, o, dir, remaining)
            if not q.result:
                remaining = -1.0
            elif surface_present(cut, tri0 + q.face, q.u, q.v, 1.0 - q.u - q.v):  # warp: p = p0*u + p1*v + p2*(1-u-v)
                blocked = True
            else:
                step = q.t + 1.0e-5 * (1.0 + q.t)
                o = o + dir * step
                remaining = remaining - step
    if remaining > 0.0 and not blocked:
        return True
    return blocked


@wp.func
def nearest_from(mesh: wp.uint64, tri0: int, cut: Surfaces, has_cutouts: int, start: wp.vec3, dir: wp.vec3, remaining: float,
                 travelled: float):
    """The nearest surface an eye ray meets in ``mesh`` (face ``f`` is the triangle ``tri0 + f`` of
    ``cut``) along start + s*dir, s in (0, remaining): back faces of single-sided meshes skipped,
    alpha-tested through cutouts (up to 64 surfaces stepped past). Returns (found 0/1, ``travelled``
    plus the distance to the hit, triangle, u, v, the triangle's geometric normal in the mesh's frame)."""
    found = int(0)
    face = int(-1)
    bu = float(0.0)
    bv = float(0.0)
    n = wp.vec3(0.0)
    o = start
    for _k in range(64):
        if found == 0 and remaining > 0.0:
            q = wp.mesh_query_ray(mesh, o, dir, remaining)
            if not q.result:
                remaining = -1.0
            else:
                tri = tri0 + q.face
                ok = q.sign > 0.0 or cut.double_sided[tri] != 0
                if ok and has_cutouts != 0:
                    ok = surface_present(cut, tri, q.u, q.v, 1.0 - q.u - q.v)
                if ok:
                    found = 1
                    face = tri
                    bu = q.u
                    bv = q.v
                    n = q.normal
                    travelled += q.t
                else:
                    step = q.t + 1.0e-5 * (1.0 + q.t)
                    o = o + dir * step
                    travelled += step
                    remaining -= step
    return found, travelled, face, bu, bv, n


@wp.func
def occluded(mesh: wp.uint64, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float) -> bool:
    """Is the segment origin + t*dir, t in (0, max_t), blocked by the soup? (:func:`occluded_from`)."""
    return occluded_from(mesh, 0, cut, has_cutouts, origin, dir, max_t)


CULL_SKIP = wp.constant(2)  # a cull flag: the light-view rasterizer skips the triangle whichever way it faces


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
    packed: tuple | None = None  # (PackedBVH or None, its stats), built by wsoft.scene.packets.packed_bvh on first use
    linked: dict = field(default_factory=dict)  # excluded prims -> (Surfaces, has_cutouts), built by shadow_surfaces

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
        from wsoft.errors import SceneError

        raise SceneError("the stage has no visible mesh triangles", file=scene.path)
    from wsoft.scene.instancing import empty_instances, upload_instances

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


def without_culling(cut: Surfaces, triangles: int, device: str) -> Surfaces:
    """``cut`` with every triangle kept (no far-face skipping): for passes that must meet every
    triangle a ray can (an irregular z-buffer's exact tests, an inner-coverage map)."""
    return surfaces_with_cull(cut, wp.zeros(max(triangles, 1), dtype=wp.int32, device=device))


def surfaces_with_cull(cut: Surfaces, cull: wp.array) -> Surfaces:
    """``cut`` (every field shared) with other far-face culling flags."""
    s = Surfaces()
    for name in Surfaces.vars:
        setattr(s, name, getattr(cut, name))
    s.cull = cull
    return s


def shadow_surfaces(ds: DeviceScene, excluded_prims: tuple[int, ...]) -> tuple[Surfaces, int]:
    """The surfaces shadow rays of one light meet, and their ``has_cutouts`` flag: ``ds``'s own when
    ``excluded_prims`` is empty (every prim casts), else a copy in which the triangles of the
    excluded prims (a light's ``collection:shadowLink``) are a cutout with nothing present, so
    any-hit queries (:func:`occluded`, the packet traversal) continue past them as they do through
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
