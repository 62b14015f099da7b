"""Ray-traced ground truth: the visible fraction of a light, with a standard error.

For each G-buffer sample, ``samples`` shadow rays go to stratified points on the light
(rect: jittered grid in the rectangle; disk and sphere: concentric mapping onto the disk,
the sphere seen as its silhouette disk; distant: uniform in the sun's cone). Rays are
any-hit against the scene's BVH and alpha-tested through cutout triangles. A perfect-square
sample count uses a jittered ``m x m`` grid; any other count a randomly shifted rank-1
(Fibonacci) lattice. Both are unbiased; ``jitter = False`` puts samples at stratum centres
(one sample = the light's centre). Randomness is seeded by ``seed`` and the sample index.

The standard error reported per sample is ``sqrt(p(1-p)/N)`` with the pseudo-count estimate
``p = (k + 0.5)/(N + 1)`` (k visible of N): the independent-sampling error, an upper bound
for stratified sampling that never reports zero uncertainty.
"""

from __future__ import annotations

import warp as wp

from wsoft.parallel import launch_chunked
from wsoft.scene.device import Surfaces, DeviceScene, occluded
from wsoft.scene.light_gpu import LightGPU, light_sample



@wp.func
def stratified_sample(s: int, n: int, m: int, jitter: wp.vec2, shift: wp.vec2) -> wp.vec2:
    """Sample ``s`` of ``n``: jittered m x m grid when m*m == n, else a shifted rank-1 lattice.

    ``jitter`` is the offset inside the grid stratum (0.5, 0.5 = its centre); ``shift`` the
    lattice's random shift.
    """
    if m * m == n:
        gx = s % m
        gy = s // m
        jx = jitter[0]
        jy = jitter[1]
        return wp.vec2((float(gx) + jx) / float(m), (float(gy) + jy) / float(m))
    x = (float(s) + 0.5) / float(n) + shift[0]
    y = float(s) * 0.6180339887498949 + 0.5 / float(n) + shift[1]
    return wp.vec2(x - wp.floor(x), y - wp.floor(y))


@wp.func
def ray_origin(p: wp.vec3, n: wp.vec3, d: wp.vec3, eps: float) -> wp.vec3:
    """Shadow-ray origin: ``p`` moved ``eps`` along the normal, to the side the ray leaves on."""
    if wp.dot(n, d) < 0.0:
        return p - n * eps
    return p + n * eps


@wp.kernel
def trace_visibility(
    offset: int,
    mesh: wp.uint64,
    cut: Surfaces,
    has_cutouts: int,
    light: LightGPU,
    pos: wp.array[wp.vec3],
    nrm: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    samples: int,
    grid: int,
    jitter: int,
    seed: int,
    eps: float,
    # outputs
    vis: wp.array[float],
    stderr: wp.array[float],
):
    i = wp.tid() + offset
    if prim[i] < 0:
        vis[i] = 1.0
        stderr[i] = 0.0
        return
    p = pos[i]
    n = nrm[i]
    state = wp.rand_init(seed, i)
    shift = wp.vec2(0.0, 0.0)
    if jitter != 0:
        shift = wp.vec2(wp.randf(state), wp.randf(state))
    visible = int(0)
    for s in range(samples):
        j = wp.vec2(0.5, 0.5)
        if jitter != 0:
            j = wp.vec2(wp.randf(state), wp.randf(state))
        u = stratified_sample(s, samples, grid, j, shift)
        r = light_sample(light, p, u[0], u[1])
        d = wp.vec3(r[0], r[1], r[2])
        if not occluded(mesh, cut, has_cutouts, ray_origin(p, n, d, eps), d, r[3] - eps):
            visible += 1
    v = float(visible) / float(samples)
    pe = (float(visible) + 0.5) / (float(samples) + 1.0)
    vis[i] = v
    stderr[i] = wp.sqrt(pe * (1.0 - pe) / float(samples))


def trace_reference(ds: DeviceScene, light: LightGPU, gb, samples: int, seed: int, jitter: bool) -> tuple[wp.array, wp.array]:
    """Visibility and its standard error per G-buffer sample (flat float32 arrays)."""
    import math

    n = gb.count
    vis = wp.empty(n, dtype=float, device=ds.device)
    err = wp.empty(n, dtype=float, device=ds.device)
    grid = int(math.isqrt(samples))
    launch_chunked(
        trace_visibility,
        n,
        inputs=[ds.mesh.id, ds.cutouts, ds.has_cutouts, light, gb.pos, gb.nrm, gb.prim, samples, grid, int(jitter), seed, ray_epsilon(ds)],
        outputs=[vis, err],
        device=ds.device,
        min_chunk=256,
    )
    return vis, err


def ray_epsilon(ds: DeviceScene) -> float:
    """Offset of shadow-ray origins along the normal, relative to the scene's size."""
    return 2.0e-5 * ds.diagonal


# -- explicit rays: the same shadow rays as arrays (for throughput comparisons with other tracers) --


@wp.kernel
def generate_shadow_rays(
    offset: int,
    light: LightGPU,
    pos: wp.array[wp.vec3],
    nrm: wp.array[wp.vec3],
    pix: wp.array[wp.int32],
    samples: int,
    grid: int,
    seed: int,
    eps: float,
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
):
    r = wp.tid() + offset
    k = r // samples
    s = r - k * samples
    i = pix[k]
    p = pos[i]
    n = nrm[i]
    state = wp.rand_init(seed, r)
    shift = wp.vec2(wp.randf(state), wp.randf(state))
    j = wp.vec2(wp.randf(state), wp.randf(state))
    u = stratified_sample(s, samples, grid, j, shift)
    ls = light_sample(light, p, u[0], u[1])
    d = wp.vec3(ls[0], ls[1], ls[2])
    origin[r] = ray_origin(p, n, d, eps)
    dir[r] = d
    tmax[r] = ls[3] - eps


@wp.kernel
def trace_shadow_rays(
    offset: int,
    mesh: wp.uint64,
    cut: Surfaces,
    has_cutouts: int,
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    # outputs
    hit: wp.array[wp.int32],
):
    r = wp.tid() + offset
    if occluded(mesh, cut, has_cutouts, origin[r], dir[r], tmax[r]):
        hit[r] = 1
    else:
        hit[r] = 0


def shadow_rays(ds: DeviceScene, light: LightGPU, gb, samples: int, seed: int = 0):
    """Origins, unit directions and lengths of ``samples`` shadow rays per covered G-buffer sample."""
    import math

    import numpy as np

    covered = np.nonzero(gb.prim.numpy() >= 0)[0].astype(np.int32)
    pix = wp.array(covered, dtype=wp.int32, device=ds.device)
    n = len(covered) * samples
    o = wp.empty(n, dtype=wp.vec3, device=ds.device)
    d = wp.empty(n, dtype=wp.vec3, device=ds.device)
    t = wp.empty(n, dtype=float, device=ds.device)
    launch_chunked(generate_shadow_rays, n, inputs=[light, gb.pos, gb.nrm, pix, samples, int(math.isqrt(samples)), seed, ray_epsilon(ds)], outputs=[o, d, t], device=ds.device)
    return o, d, t


def trace_rays(ds: DeviceScene, origin: wp.array, dir: wp.array, tmax: wp.array) -> wp.array:
    """Occlusion (1 = blocked) of explicit rays, chunked across CPU threads."""
    hit = wp.empty(origin.shape[0], dtype=wp.int32, device=ds.device)
    launch_chunked(trace_shadow_rays, origin.shape[0], inputs=[ds.mesh.id, ds.cutouts, ds.has_cutouts, origin, dir, tmax], outputs=[hit], device=ds.device, min_chunk=4096)
    return hit
