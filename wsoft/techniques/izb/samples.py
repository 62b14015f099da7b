"""The shadow samples of ``izb``: one per pixel (the G-buffer's, at the pixel centre) and, for
multi-sampled pixels, sub-pixel samples on the centre's plane or at re-cast eye rays
(:func:`sub_samples`); each with its shadow ray toward the light's centre (:func:`shadow_ray`)
and a state. :func:`place_samples` builds them for one light; :func:`resolve_samples` turns the
light pass's verdicts into per-pixel visibility.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.light import LightGPU, light_center_dir, lit_along
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU, subpixel_pattern
from wsoft.raster.gbuffer import GBufferGPU, camera_ray, cast_primary, gb_covered, gb_pixel
from wsoft.raster.shadow_rays import ray_offset, ray_origin
from wsoft.scene.surfaces import Surfaces
from wsoft.scene.instancing import InstancesGPU

SUBSAMPLES = ("auto", "recast", "plane", "gbuffer")  # where sub-samples lie (IZBParams.subsamples), in the kernels' order
BACKGROUND, TEST, HORIZON = 0, 1, 2  # sample states


@wp.func
def shadow_ray(L: LightGPU, p: wp.vec3, n: wp.vec3, eps: float, dmax: float):
    """A sample's ray toward the light's centre: (origin off the surface, unit direction, length,
    state TEST, or HORIZON where the centre lies behind the tangent plane or the sample behind a
    rect or disk light's emitting plane). ``dmax >= 0``
    (``inputs:shadow:distance``): the ray ends that far from the surface point."""
    off = ray_offset(p, eps)
    o = ray_origin(p, n, off)
    c = light_center_dir(L, o)
    d = wp.vec3(c[0], c[1], c[2])
    state = int(1)
    if not lit_along(L, n, d):
        state = 2
    t = c[3]
    if dmax >= 0.0:
        t = wp.max(wp.min(t, dmax - off), 0.0)
    return o, d, t, state


@wp.func
def store_sample(
    i: int,
    found: bool,
    L: LightGPU,
    p: wp.vec3,
    n: wp.vec3,
    eps: float,
    dmax: float,
    may_insert: bool,
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
):
    """Sample i: its shadow ray and state (BACKGROUND where ``found`` is false); inserted when it
    needs a test and ``may_insert``."""
    if not found:
        state[i] = 0
        insert[i] = 0
        origin[i] = wp.vec3(0.0)
        dir[i] = wp.vec3(0.0)
        tmax[i] = 0.0
        return
    o, d, t, st = shadow_ray(L, p, n, eps, dmax)
    origin[i] = o
    dir[i] = d
    tmax[i] = t
    state[i] = st
    insert[i] = wp.where(st == 1 and may_insert, 1, 0)


@wp.kernel
def centre_samples(
    offset: int,
    L: LightGPU,
    gb: GBufferGPU,
    eps: float,
    dmax: float,
    multi: wp.array[wp.int32],
    keep_centre: int,
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
):
    """The G-buffer's samples (pixel centres); inserted unless their pixel is multi-sampled and
    does not ``keep_centre``."""
    i = wp.tid() + offset
    store_sample(i, gb_covered(gb, i), L, gb.pos[i], gb.nrm[i], eps, dmax, multi[i] < 0 or keep_centre != 0, origin, dir, tmax, state,
                 insert)


@wp.kernel
def sub_samples(
    offset: int,
    base: int,
    n_sub: int,
    pixels: wp.array[wp.int32],
    pattern: wp.array[wp.vec2],
    mesh: wp.uint64,
    inst: InstancesGPU,
    cut: Surfaces,
    has_cutouts: int,
    cam: CameraGPU,
    gb: GBufferGPU,
    mixed: wp.array[wp.int32],
    mode: int,
    probed: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    hit_pos: wp.array[wp.vec3],
    hit_nrm: wp.array[wp.vec3],
    hit_found: wp.array[wp.int32],
    ms_pos: wp.array[wp.vec3],
    ms_nrm: wp.array[wp.vec3],
    ms_found: wp.array[wp.int32],
    L: LightGPU,
    eps: float,
    dmax: float,
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
    recast: wp.array[wp.int32],
):
    """Sub-sample s of multi-sampled pixel j at its sub-pixel offset: on the plane of the pixel's
    centre (where the camera ray meets it: no scene query) or by re-casting its eye ray through the
    scene. ``mode`` (:data:`SUBSAMPLES`): 0 auto — on the plane where the pixel sees that plane
    alone (``mixed`` 0, :func:`other_surface_near`), else re-cast; 1 recast — always; 2 plane —
    always on the plane (re-cast only where the ray misses it); 3 gbuffer — the sample of the
    multi-sampled G-buffer (``ms_*``, :func:`trace_multisampled`) at the same point. A pixel the
    stencil ``probed`` (:func:`bounds_stencil`) takes the hits its eye rays found there (the same
    rays, the same answer). ``recast`` = 1 where re-cast here, 2 where the stencil's hit was
    taken, 3 where the multi-sampled G-buffer's was."""
    k = wp.tid() + offset
    j = k / n_sub
    s = k - j * n_sub
    pix = pixels[j]
    xy = gb_pixel(gb, pix)
    off = pattern[s]
    fx = float(xy[0]) + off[0]
    fy = float(xy[1]) + off[1]
    recast[k] = 1
    if mode == 3:
        h = (xy[1] * gb.width + xy[0]) * n_sub + s
        recast[k] = 3
        store_sample(base + k, ms_found[h] != 0, L, ms_pos[h], ms_nrm[h], eps, dmax, True, origin, dir, tmax, state, insert)
    elif mode == 0 and mixed[pix] != 0 and probed[pix] != 0:
        h = slot[pix] * n_sub + s
        recast[k] = 2
        store_sample(base + k, hit_found[h] != 0, L, hit_pos[h], hit_nrm[h], eps, dmax, True, origin, dir, tmax, state, insert)
    elif mode == 2 or (mode == 0 and mixed[pix] == 0):
        o, d, t0, t1 = camera_ray(cam, gb.width, gb.height, fx, fy)
        pc = gb.pos[pix]
        nc = gb.nrm[pix]
        den = wp.dot(d, nc)
        if den < -1.0e-8:  # the plane faces the camera (its normal is viewer-facing)
            t = wp.dot(pc - o, nc) / den
            if t >= t0 and t <= t1:
                recast[k] = 0
                store_sample(base + k, True, L, o + d * t, nc, eps, dmax, True, origin, dir, tmax, state, insert)
    if recast[k] == 1:
        found, p, n, face, bu, bv, dist = cast_primary(mesh, cut, has_cutouts, inst, cam, gb.width, gb.height, fx, fy)
        store_sample(base + k, found != 0, L, p, n, eps, dmax, True, origin, dir, tmax, state, insert)


@wp.kernel
def centre_fallback(
    offset: int,
    base: int,
    n_sub: int,
    pixels: wp.array[wp.int32],
    state: wp.array[wp.int32],
    # outputs
    insert: wp.array[wp.int32],
    fallback: wp.array[wp.int32],
):
    """A multi-sampled pixel none of whose sub-samples hit a surface keeps its centre sample."""
    j = wp.tid() + offset
    hit = int(0)
    for s in range(n_sub):
        if state[base + j * n_sub + s] != 0:
            hit = 1
    pix = pixels[j]
    fallback[j] = 0
    if hit == 0 and state[pix] != 0:
        fallback[j] = 1
        insert[pix] = wp.where(state[pix] == 1, 1, 0)


@wp.func
def sample_visible(state: int, r: int, blocked: wp.array[wp.int32]) -> float:
    if state == 1:
        if r >= 0:
            if blocked[r] != 0:
                return 0.0
        return 1.0
    return 0.0


@wp.kernel
def resolve_izb(
    offset: int,
    gb: GBufferGPU,
    multi: wp.array[wp.int32],
    fallback: wp.array[wp.int32],
    base: int,
    n_sub: int,
    state: wp.array[wp.int32],
    rank: wp.array[wp.int32],
    blocked: wp.array[wp.int32],
    keep_centre: int,
    # outputs
    vis: wp.array[float],
):
    """A pixel's visibility: its centre sample's, or the mean over its sub-samples that hit a surface
    (with ``keep_centre``, over those and its centre sample)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    j = multi[i]
    if j >= 0 and fallback[j] == 0:
        total = float(0.0)
        hits = int(0)
        if keep_centre != 0 and state[i] != 0:
            hits += 1
            total += sample_visible(state[i], rank[i], blocked)
        for s in range(n_sub):
            q = base + j * n_sub + s
            st = state[q]
            if st != 0:
                hits += 1
                total += sample_visible(st, rank[q], blocked)
        vis[i] = total / float(hits)
        return
    vis[i] = sample_visible(state[i], rank[i], blocked)


@wp.func
def same_plane(p: wp.vec3, n: wp.vec3, q: wp.vec3, m: wp.vec3) -> bool:
    """Does the surface point (q, m) lie on the plane (p, n), to float precision?"""
    return wp.dot(m, n) >= 0.9999 and wp.abs(wp.dot(q - p, n)) <= 1.0e-4 * wp.length(q - p)


@wp.func
def other_surface_near(gb: GBufferGPU, cut: Surfaces, i: int) -> int:
    """1 where pixel i may see more than its centre's plane: a neighbour (of 8) on another plane or
    on nothing, or a cutout under its centre (a hole may open anywhere in the pixel); else 0."""
    if cut.tri_cut[gb.prim[i]] >= 0:
        return 1
    p = gb.pos[i]
    n = gb.nrm[i]
    xy = gb_pixel(gb, i)
    for k in range(9):
        nx = xy[0] + k % 3 - 1
        ny = xy[1] + k / 3 - 1
        if k != 4 and nx >= 0 and ny >= 0 and nx < gb.width and ny < gb.height:
            j = ny * gb.width + nx
            pr = gb.prim[j]
            if pr < 0:
                return 1
            if pr != gb.prim[i] and not same_plane(p, n, gb.pos[j], gb.nrm[j]):  # another triangle, maybe coplanar
                return 1
    return 0


@wp.kernel
def mixed_pixels(
    offset: int,
    gb: GBufferGPU,
    cut: Surfaces,
    # outputs
    mixed: wp.array[wp.int32],
):
    """:func:`other_surface_near` for every covered pixel (0 elsewhere)."""
    i = wp.tid() + offset
    mixed[i] = 0
    if gb_covered(gb, i):
        mixed[i] = other_surface_near(gb, cut, i)


@wp.kernel
def trace_multisampled(
    offset: int,
    n_sub: int,
    pattern: wp.array[wp.vec2],
    mesh: wp.uint64,
    inst: InstancesGPU,
    cut: Surfaces,
    has_cutouts: int,
    cam: CameraGPU,
    width: int,
    height: int,
    # outputs
    pos: wp.array[wp.vec3],
    nrm: wp.array[wp.vec3],
    found: wp.array[wp.int32],
):
    """Sample s of pixel j (entry ``j * n_sub + s``) of a multi-sampled eye view: the camera ray
    through the pattern's offset ``s`` in the pixel cast through the scene."""
    k = wp.tid() + offset
    j = k / n_sub
    s = k - j * n_sub
    y = j / width
    off = pattern[s]
    f, p, n, face, bu, bv, dist = cast_primary(mesh, cut, has_cutouts, inst, cam, width, height, float(j - y * width) + off[0],
                                               float(y) + off[1])
    pos[k] = p
    nrm[k] = n
    found[k] = f


def multisampled_gbuffer(p, ds, cam, width: int, height: int, n_sub: int, device: str) -> dict:
    """The eye view multi-sampled at ``p``'s sub-pixel pattern (``n_sub`` per pixel, every pixel):
    per sample (pixel-major) its surface point, viewer-facing normal and whether it hit a surface
    (:func:`trace_multisampled`) — the source ``subsamples=gbuffer`` reads."""
    n = width * height * n_sub
    out = {"pos": wp.empty(n, dtype=wp.vec3, device=device), "nrm": wp.empty(n, dtype=wp.vec3, device=device),
           "found": wp.empty(n, dtype=wp.int32, device=device)}
    pat = subpixel_pattern(n_sub, p.pattern_kind, p.seed)
    launch_chunked(trace_multisampled, n,
                   inputs=[n_sub, wp.array(pat, dtype=wp.vec2, device=device), ds.mesh.id, ds.inst, ds.cutouts, int(ds.has_cutouts), cam,
                           width, height],
                   outputs=[out["pos"], out["nrm"], out["found"]], device=device)
    return out


def place_samples(p, gb, ds, cam, L: LightGPU, eps: float, dmax: float, n_sub: int, device: str, counters: dict,
                  stencil: wp.array | None = None, probes: dict | None = None, msaa: dict | None = None) -> dict:
    """Every shadow sample of one light: the G-buffer's, then ``n_sub`` sub-samples of each
    multi-sampled pixel (the ``stencil``'s pixels with ``aa=adaptive``, every covered pixel with
    ``supersample``); ``probes``: the bounds stencil's mixed pixels and eye-ray hits, taken instead
    of casting those rays again; ``msaa``: the multi-sampled G-buffer (:func:`multisampled_gbuffer`)
    ``subsamples=gbuffer`` reads every sub-sample from. Device arrays (origin, dir, tmax, state, insert; multi, fallback)
    and the layout (base, pixels)."""
    n0 = gb.count
    covered = gb.prim.numpy() >= 0
    if p.aa == "adaptive":
        pixels = np.flatnonzero(stencil.numpy() & covered).astype(np.int32)
    elif p.aa == "supersample":
        pixels = np.flatnonzero(covered).astype(np.int32)
    else:
        pixels = np.zeros(0, np.int32)
    multi_h = np.full(n0, -1, np.int32)
    multi_h[pixels] = np.arange(len(pixels), dtype=np.int32)
    total = n0 + len(pixels) * n_sub
    arr = {
        "origin": wp.empty(total, dtype=wp.vec3, device=device), "dir": wp.empty(total, dtype=wp.vec3, device=device),
        "tmax": wp.empty(total, dtype=float, device=device), "state": wp.empty(total, dtype=wp.int32, device=device),
        "insert": wp.empty(total, dtype=wp.int32, device=device),
    }
    outs = [arr["origin"], arr["dir"], arr["tmax"], arr["state"], arr["insert"]]
    multi = wp.array(multi_h, dtype=wp.int32, device=device)
    pix = wp.array(pixels if len(pixels) else np.zeros(1, np.int32), dtype=wp.int32, device=device)
    fallback = wp.zeros(max(len(pixels), 1), dtype=wp.int32, device=device)
    launch_chunked(centre_samples, n0, inputs=[L, gb.gpu(), eps, dmax, multi, int(p.keep_centre)], outputs=outs, device=device)
    if len(pixels):
        pat = subpixel_pattern(n_sub, p.pattern_kind, p.seed)
        mode = SUBSAMPLES.index(p.subsamples)
        none1 = wp.zeros(1, dtype=wp.int32, device=device)
        hits = {"pos": wp.zeros(1, dtype=wp.vec3, device=device), "nrm": wp.zeros(1, dtype=wp.vec3, device=device), "found": none1,
                "slot": none1, "probed": wp.zeros(n0, dtype=wp.int32, device=device), "mixed": none1}
        if probes is not None:  # the stencil's mixed pixels and the hits of the eye rays it cast
            hits = probes
        elif p.subsamples == "auto":
            hits["mixed"] = wp.empty(n0, dtype=wp.int32, device=device)
            launch_chunked(mixed_pixels, n0, inputs=[gb.gpu(), ds.cutouts], outputs=[hits["mixed"]], device=device)
        mixed = hits["mixed"]
        ms = msaa if msaa is not None else {"pos": hits["pos"], "nrm": hits["nrm"], "found": none1}
        if (msaa is None) != (p.subsamples != "gbuffer"):
            raise ValueError("subsamples=gbuffer reads the multi-sampled G-buffer, and only it")
        recast = wp.empty(len(pixels) * n_sub, dtype=wp.int32, device=device)
        launch_chunked(sub_samples, len(pixels) * n_sub,
                       inputs=[n0, n_sub, pix, wp.array(pat, dtype=wp.vec2, device=device), ds.mesh.id, ds.inst, ds.cutouts,
                               int(ds.has_cutouts), cam, gb.gpu(), mixed, mode, hits["probed"], hits["slot"], hits["pos"],
                               hits["nrm"], hits["found"], ms["pos"], ms["nrm"], ms["found"], L, eps, dmax],
                       outputs=outs + [recast], device=device)
        rc = recast.numpy()
        counters["subsamples_recast"] = int((rc == 1).sum())
        counters["subsamples_from_stencil"] = int((rc == 2).sum())
        counters["subsamples_from_gbuffer"] = int((rc == 3).sum())
        launch_chunked(centre_fallback, len(pixels), inputs=[n0, n_sub, pix, arr["state"]], outputs=[arr["insert"], fallback], device=device)
    st = arr["state"].numpy()
    counters.setdefault("subsamples_recast", 0)
    counters.setdefault("subsamples_from_stencil", 0)
    counters.setdefault("subsamples_from_gbuffer", 0)
    counters["multisampled_pixels"] = int(len(pixels))
    counters["extra_samples"] = int(len(pixels) * n_sub)
    counters["centre_fallbacks"] = int(fallback.numpy()[: len(pixels)].sum())
    counters["horizon_samples"] = int((st == HORIZON).sum())
    arr.update(multi=multi, fallback=fallback, base=n0, pixels=len(pixels))
    return arr


def resolve_samples(gb, smp: dict, rank: wp.array, blocked: wp.array, n_sub: int, device: str, keep_centre: bool = False) -> wp.array:
    """Per G-buffer sample visibility (flat float32): its centre sample's verdict, or the mean over
    its sub-samples that hit a surface (``keep_centre``: and its centre sample)."""
    vis = wp.empty(gb.count, dtype=float, device=device)
    launch_chunked(resolve_izb, gb.count,
                   inputs=[gb.gpu(), smp["multi"], smp["fallback"], smp["base"], max(n_sub, 1), smp["state"], rank, blocked,
                           int(keep_centre)],
                   outputs=[vis], device=device)
    return vis
