"""Per-triangle surfaces on a Warp device and what rays ask of them.

:class:`Surfaces` holds, over a device scene's combined triangle space
(:mod:`wsoft.scene.instancing`), each triangle's cutout, sidedness and light-view cull flag,
with the cutouts' alpha textures. Kernels call :func:`surface_present` to alpha-test a point on a
triangle; scenes without cutouts pass ``has_cutouts = 0`` and never sample. :func:`occluded_from`
(any-hit), :func:`nearest_blocker_from` (a shadow ray's nearest blocker) and :func:`nearest_from`
(the eye ray's nearest surface) walk one ``wp.Mesh`` through the cutouts' holes (and, for the eye
ray, past culled back faces), each step to a few ulps past the surface's plane
(:func:`~wsoft.scene.offsets.step_past`); :mod:`wsoft.scene.rays` composes them over the soup and
the instances.
"""

from __future__ import annotations

import warp as wp

from wsoft.scene.offsets import mesh_hit, step_past


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
    tex_border: wp.array[wp.float32]  # [X] the value outside the image under the black wrap (the texture's bias)
    tex_data: wp.array[wp.float32]  # all textures, rows bottom-up: each UsdUVTexture's output, scale and bias applied


@wp.func
def wrap_coord(i: int, n: int, mode: int) -> int:
    """Texel index under a UsdUVTexture wrap mode (0 repeat, 1 mirror, 2 clamp, 3 black: -1 outside;
    ``useMetadata`` is resolved to one of them at load, :mod:`wsoft.scene.usd_texture`)."""
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
        return cut.tex_border[t]
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
                o, step = step_past(mesh, q.face, q.u, q.v, o, dir)
                remaining = remaining - step
    if remaining > 0.0 and not blocked:
        return True
    return blocked


@wp.func
def nearest_blocker_from(mesh: wp.uint64, tri0: int, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3,
                         max_t: float) -> float:
    """The distance along the segment origin + t*dir, t in (0, max_t), to the nearest surface of
    ``mesh`` (face ``f`` is the triangle ``tri0 + f`` of ``cut``) that blocks it, or -1 when none
    does: a closest-hit shadow query, both sides of every triangle, alpha-tested through cutouts as
    :func:`occluded_from` is (the same walk, so the same rays are blocked; 64 cutout layers crossed
    count as blocked where the walk gives up)."""
    if has_cutouts == 0:
        q0 = wp.mesh_query_ray(mesh, origin, dir, max_t)
        if q0.result:
            return q0.t
        return -1.0
    o = origin
    remaining = max_t
    travelled = float(0.0)
    hit = float(-1.0)
    for _k in range(64):
        if remaining > 0.0 and hit < 0.0:
            q = wp.mesh_query_ray(mesh, o, dir, remaining)
            if not q.result:
                remaining = -1.0
            elif surface_present(cut, tri0 + q.face, q.u, q.v, 1.0 - q.u - q.v):
                hit = travelled + q.t
            else:
                o, step = step_past(mesh, q.face, q.u, q.v, o, dir)
                travelled += step
                remaining = remaining - step
    if remaining > 0.0 and hit < 0.0:
        hit = travelled
    return hit


@wp.func
def nearest_from(mesh: wp.uint64, tri0: int, cut: Surfaces, has_cutouts: int, start: wp.vec3, dir: wp.vec3, remaining: float,
                 travelled: float):
    """The nearest surface an eye ray meets in ``mesh`` (face ``f`` is the triangle ``tri0 + f`` of
    ``cut``) along start + s*dir, s in (0, remaining): back faces of single-sided meshes skipped,
    alpha-tested through cutouts (up to 64 surfaces stepped past, each to the far side of its plane,
    :func:`~wsoft.scene.offsets.step_past`). Returns (found 0/1, ``travelled`` plus the distance to
    the hit, triangle, u, v, the triangle's unit geometric normal, the hit point from the triangle's
    corners and the triangle's :func:`~wsoft.scene.offsets.triangle_scale`, all in the mesh's frame)."""
    found = int(0)
    face = int(-1)
    bu = float(0.0)
    bv = float(0.0)
    n = wp.vec3(0.0)
    p = wp.vec3(0.0)
    scale = float(0.0)
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
                    p, scale, n = mesh_hit(mesh, q.face, q.u, q.v)
                    travelled += q.t
                else:
                    o, step = step_past(mesh, q.face, q.u, q.v, o, dir)
                    travelled += step
                    remaining -= step
    return found, travelled, face, bu, bv, n, p, scale


@wp.func
def occluded(mesh: wp.uint64, cut: Surfaces, has_cutouts: int, origin: wp.vec3, dir: wp.vec3, max_t: float) -> bool:
    """Is the segment origin + t*dir, t in (0, max_t), blocked by the soup? (:func:`occluded_from`)."""
    return occluded_from(mesh, 0, cut, has_cutouts, origin, dir, max_t)


CULL_SKIP = wp.constant(2)  # a cull flag: the light-view rasterizer skips the triangle whichever way it faces


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
