"""Ray-traced ground truth: the visible fraction of a light, with a standard error.

For each G-buffer sample, shadow rays go to the points of a light-sample pattern
(:class:`~wsoft.lightspace.samples.SamplePattern`; by default ``stratified`` and generated per
pixel: a jittered ``m x m`` grid for a perfect-square count, else a randomly shifted rank-1
(Fibonacci) lattice, both unbiased; ``regular`` puts samples at stratum centres, one sample =
the light's centre). Rect lights take the points in the rectangle; disk and sphere lights
through the concentric map onto the disk (an elliptical disk's scaled by its semi-axes; the
sphere seen as its silhouette disk, an ellipsoid as its silhouette ellipse); cylinder lights in
their silhouette rectangle seen from the point (a line light on its segment,
:func:`~wsoft.lightspace.light.silhouette_rect`); distant lights uniformly in the sun's cone. A
sample counts only where its ray leaves the receiver's visible side and the light emits back along
it (a rect or disk light from its front only: :func:`~wsoft.lightspace.light.lit_along`). A shaped
light's samples (``UsdLux.ShapingAPI``: cone, focus, IES profile) are weighted by its shaped
emission from the sample toward the receiver, ``V = sum(visible w) / sum(w)``
(:func:`weighted_fraction`, docs/outputs.md "V of a shaped area light"). Rays are
any-hit against the scene's BVH and alpha-tested through cutout triangles. Randomness is seeded by
the pattern's seed, the receiver and the sample index (counter-based draws,
:func:`~wsoft.lightspace.samples.counter_draw`).

Two traversals give the same answer bit for bit (``tests/test_packets.py``; three kinds of
exception found, all at float precision on a shared edge or a cutout's hole, where the packet
agrees with the brute force and Warp's per-ray walk does not, :mod:`wsoft.reference.packets`):
``packet`` (the default on CPU) traces a receiver's samples in packets of 32 rays through the BVH together
(:mod:`wsoft.reference.packets`: all start at the receiver and fan out over the light; where
Warp's BVH layout is not the one it reads, :func:`~wsoft.reference.layout.bvh_layout_error`,
``ray`` instead, with one warning), ``ray``
traces each with Warp's ``mesh_query_ray_anyhit`` (the default on CUDA, where a thread holding
32 rays would spill its registers, and below 8 samples, where a packet's set-up costs more than
it saves).

The standard error reported per sample is ``sqrt(p(1-p)/N)`` with the pseudo-count estimate
``p = (k + 0.5)/(N + 1)`` (k visible of N): the independent-sampling error, an upper bound
for stratified sampling that never reports zero uncertainty.
"""

from __future__ import annotations

import warp as wp

import wsoft.parallel  # noqa: F401  (Warp configured before this package's kernels are defined)
from wsoft.lightspace.light import LightGPU, light_point, lit_along, sample_weight
from wsoft.lightspace.samples import LightSamples, SamplePattern, sample_coords
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.raster.shadow_rays import receiver_begin, shadow_ray_length
from wsoft.lightspace.bitmask import popcount
from wsoft.errors import ParameterError
from wsoft.reference.layout import PACKETS_MODULE, bvh_layout_error
from wsoft.reference.packets import PACKET, PackedBVH, packed_bvh, packet_f, trace_receiver_packet
from wsoft.scene.device import DeviceScene, shadow_surfaces
from wsoft.scene.rays import Occluders, occluders, unoccluded
from wsoft.scene.surfaces import Surfaces

TRAVERSALS = ("auto", "packet", "ray")


@wp.func
def visible_fraction(visible: int, samples: int):
    """(V, its standard error) from ``visible`` of ``samples`` rays (pseudo-count estimate)."""
    pe = (float(visible) + 0.5) / (float(samples) + 1.0)
    return float(visible) / float(samples), wp.sqrt(pe * (1.0 - pe) / float(samples))


@wp.func
def weighted_fraction(v: float, e: float, sw: float, sv: float, sww: float):
    """(V, its standard error) of a shaped light: ``V = sv / sw``, the visible samples' shaping
    weights over all samples' (``sw``; ``sww`` their squares), its error that of ``n = sw^2 / sww``
    effective samples (at least 1; pseudo-count estimate as :func:`visible_fraction`). Where the
    weights sum to under 1e-20 (the shaped light sends next to nothing toward the receiver: it is
    masked, docs/outputs.md; their squares would underflow float32) the unweighted ``v``, ``e``."""
    if sw <= 1.0e-20:
        return v, e
    vw = wp.clamp(sv / sw, 0.0, 1.0)
    n = wp.max((sw / wp.sqrt(wp.max(sww, 1.0e-37))) * (sw / wp.sqrt(wp.max(sww, 1.0e-37))), 1.0)
    pe = (vw * n + 0.5) / (n + 1.0)
    return vw, wp.sqrt(pe * (1.0 - pe) / n)


def visibility_kernel(shaped: bool):
    """:func:`trace_visibility`; ``shaped``: each sample weighted by the shaped emission toward the
    receiver (:func:`~wsoft.lightspace.light.sample_weight`, :func:`weighted_fraction`), compiled in
    only then (an unshaped light's kernel is the plain fraction, bit for bit)."""

    def trace_visibility(
        offset: int,
        occ: Occluders,
        light: LightGPU,
        ls: LightSamples,
        gb: GBufferGPU,
        dmax: float,
        # outputs
        vis: wp.array[float],
        stderr: wp.array[float],
    ):
        i = wp.tid() + offset
        if not gb_covered(gb, i):
            vis[i] = 1.0
            stderr[i] = 0.0
            return
        p = gb.pos[i]
        n = gb.nrm[i]
        off, o, state, base, rot = receiver_begin(gb, ls, i)
        visible = int(0)
        samples = ls.count
        sw = float(0.0)
        sv = float(0.0)
        sww = float(0.0)
        for s in range(samples):
            c, state = sample_coords(ls, state, base, rot, s)
            r = light_point(light, p, c)
            d = wp.vec3(r[0], r[1], r[2])
            w = float(0.0)
            if wp.static(shaped):
                w = sample_weight(light, d)
                sw += w
                sww += w * w
            if lit_along(light, n, d):
                tm = shadow_ray_length(r[3], dmax, off)
                if unoccluded(occ, o, d, tm):
                    visible += 1
                    if wp.static(shaped):
                        sv += w
        v, e = visible_fraction(visible, samples)
        if wp.static(shaped):
            v, e = weighted_fraction(v, e, sw, sv, sww)
        vis[i] = v
        stderr[i] = e

    if shaped:
        trace_visibility.__name__ = trace_visibility.__qualname__ = "trace_visibility_shaped"
    else:
        trace_visibility.__qualname__ = "trace_visibility"
    return wp.kernel(trace_visibility, module=__name__)


trace_visibility = visibility_kernel(False)
trace_visibility_shaped = visibility_kernel(True)


@wp.func
def packet_rays(light: LightGPU, ls: LightSamples, state: wp.uint32, base: int, rot: wp.vec4, p: wp.vec3, n: wp.vec3, off: float,
                dmax: float, first: int):
    """A receiver's packet of samples ``first ..`` (at most :data:`PACKET`): the rays' unit
    directions (``dx``, ``dy``, ``dz``), lengths (``tm``), the mask of those traced (a ray behind the
    receiver's tangent plane or the light's back is not) and the advanced random state."""
    dx = packet_f()
    dy = packet_f()
    dz = packet_f()
    tm = packet_f()
    mask = wp.uint32(0)
    for k in range(wp.min(PACKET, ls.count - first)):
        c, state = sample_coords(ls, state, base, rot, first + k)
        r = light_point(light, p, c)
        d = wp.vec3(r[0], r[1], r[2])
        if lit_along(light, n, d):  # behind the tangent plane (the surface's own sheet) or the light's back: not traced
            dx[k] = d[0]
            dy[k] = d[1]
            dz[k] = d[2]
            tm[k] = shadow_ray_length(r[3], dmax, off)
            mask = mask | (wp.uint32(1) << wp.uint32(k))
    return dx, dy, dz, tm, mask, state


@wp.func
def packet_weights(light: LightGPU, ls: LightSamples, state: wp.uint32, base: int, rot: wp.vec4, p: wp.vec3, first: int,
                   live: wp.uint32, sw: float, sv: float, sww: float):
    """``sw``, ``sv``, ``sww`` of :func:`weighted_fraction` plus a packet's samples ``first ..``
    (regenerated from the random ``state`` :func:`packet_rays` started from; ``live``: the bits of
    those unblocked)."""
    for k in range(wp.min(PACKET, ls.count - first)):
        c, state = sample_coords(ls, state, base, rot, first + k)
        r = light_point(light, p, c)
        w = sample_weight(light, wp.vec3(r[0], r[1], r[2]))
        sw += w
        sww += w * w
        if (live >> wp.uint32(k)) & wp.uint32(1) != wp.uint32(0):
            sv += w
    return sw, sv, sww


def packets_kernel(shaped: bool):
    """:func:`trace_visibility_packets`; ``shaped`` as :func:`visibility_kernel`."""

    def trace_visibility_packets(
        offset: int,
        mesh: wp.uint64,
        pb: PackedBVH,
        cut: Surfaces,
        has_cutouts: int,
        light: LightGPU,
        ls: LightSamples,
        gb: GBufferGPU,
        dmax: float,
        # outputs
        vis: wp.array[float],
        stderr: wp.array[float],
        given_up: wp.array[wp.int32],
    ):
        """:func:`trace_visibility` with a receiver's samples traced in packets of :data:`PACKET`
        (the same rays, generated in the same order). Once a packet of a
        receiver gives up (its rays fan out over fine geometry, :func:`trace_packet`), the
        receiver's other samples go ray by ray; ``given_up``: 1 for such receivers."""
        i = wp.tid() + offset
        given_up[i] = 0
        if not gb_covered(gb, i):
            vis[i] = 1.0
            stderr[i] = 0.0
            return
        p = gb.pos[i]
        n = gb.nrm[i]
        off, o, state, base, rot = receiver_begin(gb, ls, i)
        visible = int(0)
        samples = ls.count
        first = int(0)
        each = int(0)
        sw = float(0.0)
        sv = float(0.0)
        sww = float(0.0)
        while first < samples:
            s0 = state
            dx, dy, dz, tm, mask, state = packet_rays(light, ls, state, base, rot, p, n, off, dmax, first)
            live, each = trace_receiver_packet(mesh, pb, cut, has_cutouts, o, dx, dy, dz, tm, mask, each)
            visible += popcount(live)
            if wp.static(shaped):
                sw, sv, sww = packet_weights(light, ls, s0, base, rot, p, first, live, sw, sv, sww)
            first += PACKET
        v, e = visible_fraction(visible, samples)
        if wp.static(shaped):
            v, e = weighted_fraction(v, e, sw, sv, sww)
        vis[i] = v
        stderr[i] = e
        given_up[i] = each

    if shaped:
        trace_visibility_packets.__name__ = trace_visibility_packets.__qualname__ = "trace_visibility_packets_shaped"
    else:
        trace_visibility_packets.__qualname__ = "trace_visibility_packets"
    return wp.kernel(trace_visibility_packets, module=PACKETS_MODULE)


trace_visibility_packets = packets_kernel(False)
trace_visibility_packets_shaped = packets_kernel(True)


# chunks a CPU thread: receivers cost unevenly (lit, penumbra, packets that give up) and chunks
# balance the threads, but each chunk costs a launch; 8 was the fastest of 2-32 on 2 threads at 320x240
# (contact and city, 16 samples: bench foundation's ray_throughput rows)
PER_THREAD = 8
PACKET_MIN_SAMPLES = 8  # below this a packet's set-up costs more than it saves (measured: bench foundation)


def resolve_traversal(traversal: str, device: str, samples: int) -> str:
    """``auto``: ``packet`` on CPU from :data:`PACKET_MIN_SAMPLES` light samples up, else ``ray``."""
    if traversal not in TRAVERSALS:
        raise ValueError(f"traversal {traversal!r} is not one of {', '.join(TRAVERSALS)}")
    if traversal == "auto":
        return "packet" if str(device).startswith("cpu") and samples >= PACKET_MIN_SAMPLES else "ray"
    return traversal


def reference_pattern(samples: int, seed: int, jitter: bool) -> SamplePattern:
    """The reference's default sampling: stratified per pixel (``jitter = False``: stratum centres)."""
    return SamplePattern("stratified" if jitter else "regular", samples, seed=seed, per_pixel=True)


def trace_reference(ds: DeviceScene, light: LightGPU, gb, pattern: SamplePattern, disk: bool, traversal: str = "auto",
                    counters: dict | None = None, excluded: tuple[int, ...] = (), max_distance: float = -1.0) -> tuple[wp.array, wp.array]:
    """Visibility and its standard error per G-buffer sample (flat float32 arrays), with the
    light samples of ``pattern`` (mapped onto a disk when ``disk``), each from a few ulps off its surface
    (:func:`~wsoft.raster.shadow_rays.receiver_begin`); ``traversal``: ``packet``, ``ray`` or ``auto``
    (:func:`resolve_traversal`).
    ``excluded``: prims (indices into the scene's prims) that cast no shadow of this light (its
    ``collection:shadowLink``): rays continue past them (:func:`~wsoft.scene.device.shadow_surfaces`).
    ``max_distance``: ``inputs:shadow:distance`` (>= 0: a ray looks for casters only that far from
    the receiver; -1: up to the light).
    ``counters`` (a dict) receives ``traversal`` (the one used), ``packet_fallback`` (why not
    packets, when the BVH is too deep for them) and ``receivers_ray_by_ray`` (receivers whose
    packets gave up: their rays fan out over fine geometry)."""
    n = gb.count
    dmax = float(max_distance) if max_distance >= 0.0 else -1.0
    vis = wp.empty(n, dtype=float, device=ds.device)
    err = wp.empty(n, dtype=float, device=ds.device)
    mode = resolve_traversal(traversal, ds.device, pattern.count)
    if ds.instances is not None and mode == "packet":  # packets walk the soup's BVH only: rays reach instances one by one
        if traversal == "packet":
            raise ParameterError("traversal=packet does not reach instances (the stage was loaded with instancing): "
                                 "use traversal=ray or auto, or load it flattened")
        mode = "ray"
    if mode == "packet" and bvh_layout_error(ds.device) is not None:  # warned once per process
        mode = "ray"
    pb, pstats = packed_bvh(ds) if mode == "packet" else (None, {})
    if mode == "packet" and pb is None:  # a BVH too deep for the packets' stack
        mode = "ray"
        if counters is not None:
            counters["packet_fallback"] = pstats["error"]
    if counters is not None:
        counters["traversal"] = mode
    if mode == "packet":
        cut, has_cutouts = shadow_surfaces(ds, excluded)
        given_up = wp.empty(n, dtype=wp.int32, device=ds.device)
        launch_chunked(
            trace_visibility_packets_shaped if light.shaped else trace_visibility_packets,
            n,
            inputs=[ds.mesh.id, pb, cut, has_cutouts, light, pattern.on(ds.device, disk), gb.gpu(), dmax],
            outputs=[vis, err, given_up],
            device=ds.device,
            min_chunk=256,
            per_thread=PER_THREAD,
        )
        if counters is not None:
            counters["receivers_ray_by_ray"] = int(given_up.numpy().sum())
        return vis, err
    launch_chunked(
        trace_visibility_shaped if light.shaped else trace_visibility,
        n,
        inputs=[occluders(ds, excluded), light, pattern.on(ds.device, disk), gb.gpu(), dmax],
        outputs=[vis, err],
        device=ds.device,
        min_chunk=256,
        per_thread=PER_THREAD,
    )
    return vis, err


# -- explicit rays: the same shadow rays as arrays (for throughput comparisons with other tracers) --


@wp.kernel
def generate_shadow_rays(
    offset: int,
    light: LightGPU,
    ls: LightSamples,
    gb: GBufferGPU,
    pix: wp.array[wp.int32],
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
):
    k = wp.tid() + offset
    i = pix[k]
    p = gb.pos[i]
    n = gb.nrm[i]
    off, o, state, base, rot = receiver_begin(gb, ls, i)
    samples = ls.count
    for s in range(samples):
        c, state = sample_coords(ls, state, base, rot, s)
        r = light_point(light, p, c)
        d = wp.vec3(r[0], r[1], r[2])
        origin[k * samples + s] = o
        dir[k * samples + s] = d
        tmax[k * samples + s] = wp.where(lit_along(light, n, d), r[3] - off, 0.0)  # behind a plane: blocked, not traced


@wp.kernel
def trace_shadow_rays(
    offset: int,
    occ: Occluders,
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    # outputs
    hit: wp.array[wp.int32],
):
    r = wp.tid() + offset
    if unoccluded(occ, origin[r], dir[r], tmax[r]):
        hit[r] = 0
    else:
        hit[r] = 1


def shadow_rays(ds: DeviceScene, light: LightGPU, gb, pattern: SamplePattern, disk: bool):
    """Origins, unit directions and lengths of the shadow rays of every covered G-buffer sample:
    the same rays the reference traces with ``pattern``, ``pattern.count`` per sample."""
    import numpy as np

    covered = np.nonzero(gb.prim.numpy() >= 0)[0].astype(np.int32)
    pix = wp.array(covered, dtype=wp.int32, device=ds.device)
    n = len(covered) * pattern.count
    o = wp.empty(n, dtype=wp.vec3, device=ds.device)
    d = wp.empty(n, dtype=wp.vec3, device=ds.device)
    t = wp.empty(n, dtype=float, device=ds.device)
    launch_chunked(generate_shadow_rays, len(covered), inputs=[light, pattern.on(ds.device, disk), gb.gpu(), pix],
                   outputs=[o, d, t], device=ds.device, min_chunk=256)
    return o, d, t


@wp.kernel(module=PACKETS_MODULE)
def trace_shadow_ray_packets(
    offset: int,
    mesh: wp.uint64,
    pb: PackedBVH,
    cut: Surfaces,
    has_cutouts: int,
    per: int,
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    # outputs
    hit: wp.array[wp.int32],
):
    """Explicit rays ``per`` to a receiver (consecutive, one origin), in packets of :data:`PACKET`."""
    j = wp.tid() + offset
    o = origin[j * per]
    first = int(0)
    each = int(0)
    while first < per:
        dx = packet_f()
        dy = packet_f()
        dz = packet_f()
        tm = packet_f()
        mask = wp.uint32(0)
        cnt = wp.min(PACKET, per - first)
        for k in range(cnt):
            r = j * per + first + k
            d = dir[r]
            dx[k] = d[0]
            dy[k] = d[1]
            dz[k] = d[2]
            tm[k] = tmax[r]
            mask = mask | (wp.uint32(1) << wp.uint32(k))
        live, each = trace_receiver_packet(mesh, pb, cut, has_cutouts, o, dx, dy, dz, tm, mask, each)
        for k in range(cnt):
            hit[j * per + first + k] = wp.where((live >> wp.uint32(k)) & wp.uint32(1) != wp.uint32(0), 0, 1)
        first += PACKET


def trace_ray_packets(ds: DeviceScene, origin: wp.array, dir: wp.array, tmax: wp.array, per: int) -> wp.array:
    """Occlusion (1 = blocked) of explicit rays laid out ``per`` to a receiver with one origin
    (as :func:`shadow_rays` writes them), traced in packets; equal to :func:`trace_rays`."""
    if ds.instances is not None:
        raise ValueError("packets walk the soup's BVH only: an instanced scene's rays go through trace_rays")
    why = bvh_layout_error(ds.device)
    if why is not None:
        raise ValueError(f"packets cannot read this Warp's BVH: {why}")
    pb, pstats = packed_bvh(ds)
    if pb is None:
        raise ValueError(pstats["error"])
    hit = wp.empty(origin.shape[0], dtype=wp.int32, device=ds.device)
    launch_chunked(trace_shadow_ray_packets, origin.shape[0] // per,
                   inputs=[ds.mesh.id, pb, ds.cutouts, ds.has_cutouts, per, origin, dir, tmax], outputs=[hit],
                   device=ds.device, min_chunk=256)
    return hit


def trace_rays(ds: DeviceScene, origin: wp.array, dir: wp.array, tmax: wp.array) -> wp.array:
    """Occlusion (1 = blocked) of explicit rays, chunked across CPU threads."""
    hit = wp.empty(origin.shape[0], dtype=wp.int32, device=ds.device)
    launch_chunked(trace_shadow_rays, origin.shape[0], inputs=[occluders(ds), origin, dir, tmax], outputs=[hit], device=ds.device, min_chunk=4096)
    return hit
