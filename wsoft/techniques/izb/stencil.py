"""The shadow-edge stencils of ``izb`` with ``aa=adaptive``: the pixels that get sub-samples.

``bounds`` (:func:`bounds_stencil`): exact depth bounds of a conservative map, its back and open
faces and an inner-coverage map, per pixel plane (:func:`footprint_certainty`). ``vsm``
(:func:`edge_stencil`, the paper's): the one-tailed Chebyshev bounds of a mip-mapped variance
shadow map over the pixel's footprint. :func:`bounds_stencil_pass` and :func:`vsm_stencil_pass`
run them for one light.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.accel.pyramid import build_bounds_pyramid, build_moments_pyramid
from wsoft.lightspace.light import LightGPU, light_center_dir, lit_along
from wsoft.lightspace.moments import chebyshev_bound, moments_variance
from wsoft.lightspace.view import ViewGPU, receiver_plane_affine, receiver_plane_range, view_dir, view_of
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU, subpixel_pattern
from wsoft.raster.gbuffer import GBufferGPU, cast_primary, gb_covered, gb_pixel
from wsoft.raster.shadow_rays import ray_offset, ray_origin
from wsoft.scene.device import face_surfaces
from wsoft.scene.surfaces import CULL_SKIP, Surfaces
from wsoft.scene.instancing import InstancesGPU
from wsoft.techniques.izb.footprint import pixel_footprint
from wsoft.techniques.izb.samples import mixed_pixels, same_plane

RECEIVER_SLACK = wp.constant(3.5)  # the stencil's slack in receiver depth ranges over the texels read


@wp.func
def moments_at(pyr: wp.array[wp.vec2], off: int, size: int, x: int, y: int) -> wp.vec2:
    return pyr[off + y * size + x]


@wp.func
def chebyshev(m: wp.vec2, t: float, min_var: float, lower: int) -> float:
    """One-tailed Chebyshev bound (:func:`~wsoft.lightspace.moments.chebyshev_bound`) of the mass
    below t (``lower``) or at/above t of the distribution with moments m; 1 where t lies on the
    far side of the mean."""
    mu = m[0]
    d = mu - t
    if lower != 0:
        if d <= 0.0:
            return 1.0
    else:
        if d >= 0.0:
            return 1.0
    return chebyshev_bound(mu, moments_variance(mu, m[1], min_var), t)


@wp.kernel
def edge_stencil(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    lv: ViewGPU,
    pyr: wp.array[wp.vec2],
    pyr_shadowed: wp.array[wp.vec2],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    depth_scale: float,
    threshold: float,
    min_var: float,
    bias: float,
    listing: int,
    may_shadow: int,
    # outputs
    edge: wp.array[wp.int32],
    verdict: wp.array[wp.int32],
):
    """Potential shadow-edge pixels (1), from the mip-mapped variance shadow map: ``pyr`` for the
    certainly-lit bound, ``pyr_shadowed`` for the certainly-shadowed one (the same pyramid, or one
    of an inner-coverage map). ``verdict``: 1 certainly lit, 2 certainly shadowed, 3 both, 0
    neither or not read."""
    i = wp.tid() + offset
    edge[i] = 0
    verdict[i] = 0
    if not gb_covered(gb, i):
        return
    ok, box, zr = pixel_footprint(lv, cam, gb.width, gb.height, gb_pixel(gb, i), gb.pos[i], gb.nrm[i], 0.0, 0, 1)
    xmin = box[0]
    ymin = box[1]
    xmax = box[2]
    ymax = box[3]
    zmin = zr[0]
    zmax = zr[1]
    if ok == 0 or not (xmax - xmin < 1.0e6 and ymax - ymin < 1.0e6):
        edge[i] = 1  # a grazing or unbounded footprint: nothing can be ruled out
        return
    extent = wp.max(wp.max(xmax - xmin, ymax - ymin), 1.0e-6)
    slope = (zmax - zmin) * depth_scale / extent  # the receiver's normalised depth change per texel
    xmin -= 1.0
    ymin -= 1.0
    xmax += 1.0
    ymax += 1.0
    e = wp.max(xmax - xmin, ymax - ymin)
    lev = int(wp.ceil(wp.log2(wp.max(e, 1.0))))
    lev = wp.clamp(lev, 0, levels - 1)
    # t: the footprint's nearest depth less a slack. The texels read span up to 2^(lev+1) base texels,
    # over which the receiver's own depth (in the map as its nearest depth per texel) spreads by
    # r = slope 2^(lev+1); a receiver alone then has mean >= t_lo - r and standard deviation <= r / sqrt(12),
    # and its Chebyshev bound stays above 1% unless the mean lies 10 deviations past t: slack 3.5 r
    slack = RECEIVER_SLACK * slope * float(2 << lev) + bias
    tn = (zmin - lv.near) * depth_scale - slack
    size = map_size >> lev
    sc = 1.0 / float(1 << lev)
    x0 = int(wp.floor(xmin * sc))
    x1 = int(wp.floor(xmax * sc))
    y0 = int(wp.floor(ymin * sc))
    y1 = int(wp.floor(ymax * sc))
    if x1 < 0 or y1 < 0 or x0 >= size or y0 >= size:
        edge[i] = 1  # outside the map: nothing known
        return
    x0 = wp.clamp(x0, 0, size - 1)
    x1 = wp.clamp(x1, 0, size - 1)
    y0 = wp.clamp(y0, 0, size - 1)
    y1 = wp.clamp(y1, 0, size - 1)
    m = wp.vec2(0.0)
    ms = wp.vec2(0.0)
    cnt = float(0.0)
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            m += moments_at(pyr, level_off[lev], size, x, y)
            ms += moments_at(pyr_shadowed, level_off[lev], size, x, y)
            cnt += 1.0
    m = m / cnt
    ms = ms / cnt
    lit = chebyshev(m, tn, min_var, 1) < threshold  # occluder mass in front of the footprint: almost none
    shadowed = chebyshev(ms, tn, min_var, 0) < threshold and may_shadow != 0  # mass at or beyond it: almost none
    verdict[i] = wp.where(lit, 1, 0) + wp.where(shadowed, 2, 0)
    if listing != 0:
        if lit or shadowed:
            edge[i] = 1
    elif not lit and not shadowed:
        edge[i] = 1


@wp.func
def footprint_certainty(
    lv: ViewGPU,
    cam: CameraGPU,
    width: int,
    height: int,
    xy: wp.vec2i,
    L: LightGPU,
    p: wp.vec3,
    n: wp.vec3,
    closed: bool,
    eps: float,
    bounds: wp.array[wp.vec4],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    bias: float,
    max_texels: int,
    may_shadow: int,
) -> wp.vec2i:
    """Is the part of pixel ``xy`` on the plane (``p``, ``n``; ``closed``: of a closed surface)
    certainly lit, certainly shadowed (1 / 0 each)? Exact bounds, no probability: every texel of the
    finest pyramid level that covers the footprint in at most ``max_texels`` per side is compared
    with the plane's own depths over it (``bounds``: per texel the nearest depth of every surface,
    of the back faces of closed surfaces, of open surfaces, all rasterized conservatively, and the
    farthest depth of the inner-coverage map). Certainly lit: nothing touching the texel is nearer
    than the plane's nearest point in the texel (the receiver itself is in that map, at that
    point), no back face of a closed surface is nearer than the plane's farthest point of the
    footprint in the texel (every ray that crosses a closed blocker leaves it through a back face;
    this catches a blocker a steep plane's own depth hides in the first map) and, on a closed
    receiver, no open surface is either. Certainly shadowed: the texel is covered whole by a
    blocker nearer than the plane anywhere in the footprint's part of the texel.

    The plane is the one the samples' shadow rays start from: moved off the surface along ``n`` as
    :func:`shadow_ray` moves them (``eps``); at a grazing light that shift alone moves a point
    across texels. ``may_shadow = 0`` (a finite ``inputs:shadow:distance``, which the maps cannot
    check): never certainly shadowed by a blocker, only by the light's centre being behind the plane."""
    c = light_center_dir(L, p)
    if not lit_along(L, n, wp.vec3(c[0], c[1], c[2])):
        return wp.vec2i(0, 1)  # the centre behind the plane (or p behind the light): every sample on it is shadowed
    ok, xp, q0, gx, gy = receiver_plane_affine(lv, view_of(lv, ray_origin(p, n, ray_offset(p, eps))), view_dir(lv, n))
    if not ok:
        return wp.vec2i(0, 0)
    inside, box, zr = pixel_footprint(lv, cam, width, height, xy, p, n, eps, 1, 0)
    if inside == 0:
        return wp.vec2i(0, 0)
    xmin = box[0]
    ymin = box[1]
    xmax = box[2]
    ymax = box[3]
    # a hair wider against rounding; outside the map nothing is known
    xmin -= 0.01
    ymin -= 0.01
    xmax += 0.01
    ymax += 0.01
    fs = float(map_size)
    if not (xmin >= 0.0 and ymin >= 0.0 and xmax < fs and ymax < fs):
        return wp.vec2i(0, 0)
    lev = int(0)
    while lev < levels - 1 and (int(xmax) / (1 << lev) - int(xmin) / (1 << lev) >= max_texels
                                or int(ymax) / (1 << lev) - int(ymin) / (1 << lev) >= max_texels):
        lev += 1
    size = map_size >> lev
    side = float(1 << lev)
    tx0 = int(xmin) >> lev
    ty0 = int(ymin) >> lev
    nx = (int(xmax) >> lev) - tx0 + 1
    count = nx * ((int(ymax) >> lev) - ty0 + 1)
    lit = int(1)
    shadowed = may_shadow
    for k in range(count):
        tx = tx0 + k % nx
        ty = ty0 + k / nx
        j = level_off[lev] + ty * size + tx
        xa = float(tx) * side
        ya = float(ty) * side
        whole = receiver_plane_range(lv, xp, q0, gx, gy, xa, ya, xa + side, ya + side)
        part = receiver_plane_range(lv, xp, q0, gx, gy, wp.max(xa, xmin), wp.max(ya, ymin), wp.min(xa + side, xmax), wp.min(ya + side, ymax))
        m = bounds[j]
        if whole[0] < 0.0 or m[0] < whole[0] - bias or m[1] < part[1] - bias:
            lit = 0
        elif m[2] < wp.where(closed, part[1], whole[0]) - bias:
            lit = 0
        if part[0] < 0.0 or m[3] >= part[0] - bias:
            shadowed = 0
        if lit == 0 and shadowed == 0:
            break
    return wp.vec2i(lit, shadowed)


@wp.kernel
def bounds_stencil(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    lv: ViewGPU,
    L: LightGPU,
    bounds: wp.array[wp.vec4],
    closed_faces: wp.array[wp.int32],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    bias: float,
    max_texels: int,
    eps: float,
    may_shadow: int,
    pattern: wp.array[wp.vec2],
    mesh: wp.uint64,
    inst: InstancesGPU,
    cut: Surfaces,
    has_cutouts: int,
    mixed: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    # outputs
    edge: wp.array[wp.int32],
    probed: wp.array[wp.int32],
    hit_pos: wp.array[wp.vec3],
    hit_nrm: wp.array[wp.vec3],
    hit_found: wp.array[wp.int32],
):
    """Potential shadow-edge pixels (1) by exact depth bounds (:func:`footprint_certainty`): a pixel
    is certain when its part on its own plane is certainly lit or certainly shadowed and, where a
    neighbour's surface differs (``mixed``: a silhouette or a crease may cross the pixel), so is its
    part on the plane of every surface its sub-pixel eye rays meet (``pattern``, the sub-samples the
    pixel would get). Those rays are all cast (``probed`` = 1) and their hits kept at the pixel's
    ``slot`` for :func:`sub_samples`, which then casts none of them again."""
    i = wp.tid() + offset
    edge[i] = 0
    probed[i] = 0
    if not gb_covered(gb, i):
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    xy = gb_pixel(gb, i)
    r = footprint_certainty(lv, cam, gb.width, gb.height, xy, L, p, n, closed_faces[gb.prim[i]] != CULL_SKIP, eps, bounds, level_off,
                            levels, map_size, bias, max_texels, may_shadow)
    lit = r[0]
    shadowed = r[1]
    if lit == 0 and shadowed == 0:
        edge[i] = 1
        return
    if mixed[i] == 0:
        return
    probed[i] = 1
    ns = pattern.shape[0]
    for s in range(ns):
        off = pattern[s]
        found, q, m, face, bu, bv, dist = cast_primary(mesh, cut, has_cutouts, inst, cam, gb.width, gb.height,
                                                       float(xy[0]) + off[0], float(xy[1]) + off[1])
        h = slot[i] * ns + s
        hit_found[h] = found
        hit_pos[h] = q
        hit_nrm[h] = m
        if found != 0 and (lit != 0 or shadowed != 0):
            if not same_plane(p, n, q, m):
                r = footprint_certainty(lv, cam, gb.width, gb.height, xy, L, q, m, closed_faces[face] != CULL_SKIP, eps, bounds, level_off,
                                        levels, map_size, bias, max_texels, may_shadow)
                lit = lit * r[0]
                shadowed = shadowed * r[1]
    if lit == 0 and shadowed == 0:
        edge[i] = 1


def edge_counters(counters: dict, edge: wp.array, gb) -> wp.array:
    """``edge`` (the stencil), its pixels counted into ``counters``."""
    e = edge.numpy()
    covered = int((gb.prim.numpy() >= 0).sum())
    counters["edge_pixels"] = int(e.sum())
    counters["edge_fraction"] = float(e.sum() / covered) if covered else 0.0
    return edge


def bounds_stencil_pass(p, gb, ds, outer, back, opened, inner, cam, L: LightGPU, eps: float, may_shadow: int, n_sub: int, device: str,
                        counters: dict) -> tuple[wp.array, dict]:
    """The ``bounds`` stencil of one light from its four maps (``outer`` conservative, its ``back``
    and ``opened`` faces, the ``inner`` coverage): (the stencil, the probes: mixed pixels and the
    hits of the sub-pixel eye rays it cast, which :func:`~wsoft.techniques.izb.samples.place_samples`
    takes instead of casting them again)."""
    v = outer.view
    pyr, offs = build_bounds_pyramid([outer.depth, back.depth, opened.depth], inner.depth, device)
    closed_faces = face_surfaces(ds, v.origin if v.persp else None, "back").cull
    edge = wp.empty(gb.count, dtype=wp.int32, device=device)
    probed = wp.empty(gb.count, dtype=wp.int32, device=device)
    mixed = wp.empty(gb.count, dtype=wp.int32, device=device)
    launch_chunked(mixed_pixels, gb.count, inputs=[gb.gpu(), ds.cutouts], outputs=[mixed], device=device)
    # a slot of n_sub hits per pixel that may probe (one next to another surface); host scan: no atomics
    m = mixed.numpy()
    slot_h = np.where(m != 0, np.cumsum(m) - 1, -1).astype(np.int32)
    nhits = max(int(m.sum()) * n_sub, 1)
    hits = {"pos": wp.empty(nhits, dtype=wp.vec3, device=device), "nrm": wp.empty(nhits, dtype=wp.vec3, device=device),
            "found": wp.empty(nhits, dtype=wp.int32, device=device), "slot": wp.array(slot_h, dtype=wp.int32, device=device),
            "probed": probed, "mixed": mixed}
    pat = subpixel_pattern(n_sub, p.pattern_kind, p.seed)
    launch_chunked(bounds_stencil, gb.count,
                   inputs=[gb.gpu(), cam, v.gpu(), L, pyr, closed_faces, wp.array(offs, dtype=wp.int32, device=device), len(offs) - 1,
                           p.shadow_map_size, p.bounds_bias * max(v.far - v.near, 1e-12), p.bounds_texels,
                           eps, may_shadow, wp.array(pat, dtype=wp.vec2, device=device), ds.mesh.id, ds.inst, ds.cutouts,
                           int(ds.has_cutouts), mixed, hits["slot"]],
                   outputs=[edge, probed, hits["pos"], hits["nrm"], hits["found"]], device=device)
    counters["stencil_probed_pixels"] = int(probed.numpy().sum())
    return edge_counters(counters, edge, gb), hits


def vsm_stencil_pass(p, gb, dm, cam, may_shadow: int, device: str, counters: dict, inner=None,
                     cutouts: Surfaces | None = None) -> tuple[wp.array, wp.array]:
    """The ``vsm`` stencil of one light from its depth map ``dm`` (mip-mapped moments; ``inner``:
    an inner-coverage map of the same view, whose moments the certainly-shadowed bound reads
    instead; ``cutouts``: the scene's, to flag every pixel next to another surface as well,
    :func:`~wsoft.techniques.izb.samples.mixed_pixels`): (the stencil, the verdicts of
    :func:`edge_stencil`)."""
    v = dm.view
    pyr, offs = build_moments_pyramid(dm.depth, v.near, v.far, device)
    pyr_sh = pyr
    if inner is not None:
        iv = inner.view
        if (iv.width, iv.height, tuple(np.ravel(iv.window)), iv.near, iv.far) != (v.width, v.height, tuple(np.ravel(v.window)), v.near, v.far):
            raise ValueError("the stencil's inner-coverage map is not in its depth map's view")
        pyr_sh, _ = build_moments_pyramid(inner.depth, v.near, v.far, device)
    edge = wp.empty(gb.count, dtype=wp.int32, device=device)
    verdict = wp.empty(gb.count, dtype=wp.int32, device=device)
    scale = 1.0 / (v.far - v.near) if v.far > v.near else 1.0
    launch_chunked(edge_stencil, gb.count,
                   inputs=[gb.gpu(), cam, v.gpu(), pyr, pyr_sh, wp.array(offs, dtype=wp.int32, device=device), len(offs) - 1,
                           p.shadow_map_size, scale, p.edge_threshold, p.min_variance, p.stencil_bias,
                           int(p.stencil_rule == "listing"), may_shadow],
                   outputs=[edge, verdict], device=device)
    if cutouts is not None:
        mixed = wp.empty(gb.count, dtype=wp.int32, device=device)
        launch_chunked(mixed_pixels, gb.count, inputs=[gb.gpu(), cutouts], outputs=[mixed], device=device)
        mh = mixed.numpy() != 0
        counters["mixed_pixels_flagged"] = int((mh & (edge.numpy() == 0)).sum())
        edge = wp.array((edge.numpy() != 0) | mh, dtype=wp.int32, device=device)
    vh = verdict.numpy()
    counters["certainly_lit_pixels"] = int(((vh & 1) != 0).sum())
    counters["certainly_shadowed_pixels"] = int(((vh & 2) != 0).sum())
    return edge_counters(counters, edge, gb), verdict
