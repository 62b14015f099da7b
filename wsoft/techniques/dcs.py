"""``dcs``: depth complexity sampling (Forest, Barthe and Paulin 2008) with soft textured shadow
volumes for perforated triangles (Forest, Barthe, Guennebaud and Paulin 2009, §3).

For each receiver ``p`` (a G-buffer sample) and each light sample ``s`` (the shared generator,
:class:`~wsoft.lightspace.samples.SamplePattern`: by default 16 stratified points turned per pixel),
the *depth complexity* ``count(s)``: how many occluding layers the shadow ray ``p -> s`` crosses.
``V`` (the paper's ``v_coef``) is the fraction of samples with ``count = 0``. The shadow rays are
the reference's (:mod:`wsoft.reference`): from ``o``, ``p`` moved off its surface by
:func:`~wsoft.scene.offsets.ray_offset`, to each light point (:func:`~wsoft.lightspace.light.light_point`,
a distant light's at its ``far`` length); samples behind the receiver's tangent plane, and every
sample of a rect or disk light whose emitting side faces away from the receiver, are blocked (the
horizon, applied per sample as the reference does, :func:`~wsoft.lightspace.light.lit_along`).

What is counted. ``count(s)`` is the number of opaque triangles the segment ``o -> s`` crosses
plus the perforated triangles that block it at their alpha texture: a closed layer counts twice
(entry and exit), an open one once. The paper counts entries into closed objects; counting every
crossing needs no notion of closedness (open meshes, mixed meshes, non-manifold edges and
inconsistent winding all follow one rule), and ``V`` only asks whether the count is zero.

1. **Reference count, one ray per pixel** (:func:`count_crossings`). The opaque triangles that
   cast the light's shadow (not the cutouts: they go through STSV only; not the prims its
   ``collection:shadowLink`` leaves out) get a BVH of their own (``wp.Bvh``); one segment per
   receiver, ``o`` to the light's centre ``c`` (the silhouette disk's centre of a sphere light, the
   cone's axis of a distant light), counts every triangle it crosses with Warp's watertight
   ray-triangle test (the one the reference's any-hit uses). Where ``c`` lies behind the
   receiver's tangent plane the first sample in front of it is the reference instead: the swept
   triangle ``o, c, s`` must stay in front of the receiver's own surface (else that surface, which
   extends under the light, would enter it through its far side, which edges cannot see).
2. **Silhouette edges** (:func:`dcs_visibility`). As the light point ``x`` moves from ``c`` to
   ``s``, the segment ``o -> x`` sweeps the triangle ``o c s``, and the count changes exactly
   when an edge of the occluders crosses that triangle (Laine et al. 2005's reading of depth
   complexity: the edge projected from ``o`` onto the light is a *segment*, and only the light
   samples whose path from ``c`` crosses it change, not the half-plane of its line). An edge
   ``a b`` with faces whose far corners lie on sides ``sigma_f`` (+1/-1) of the plane through
   ``o, a, b`` (normal ``n = (a - o) x (b - o)``) adds ``(sigma_0 + sigma_1) sign(n . (s - o))``
   when ``c`` and ``s`` lie on opposite sides of that plane and the crossing point ``m`` of
   ``c s`` with it lies in the wedge ``o, a, b`` beyond the edge (``m - o = alpha (a - o) +
   beta (b - o)`` with ``alpha, beta >= 0`` and ``alpha + beta >= 1``). So a silhouette *seen from
   ``o``* (both faces on one side: ±2), an open edge (one face: ±1), and an edge whose faces lie
   on both sides (0, not a silhouette from ``o``). ``count(s) = count(c) + sum``: exact for any
   triangle mesh up to float rounding at grazing configurations; geometry that passes through the
   light itself (crossing the segment ``c s``) is not seen.
   *Potential* silhouette edges per light (:func:`~wsoft.scene.adjacency.silhouette_candidates`,
   from the welded adjacency): open and non-manifold edges, and edges whose two faces' facing can
   differ for some point of the light's bound (a local light's ball, a distant light's cone).
   An edge is a silhouette from ``o`` exactly when it is one from the light point on the line
   through ``o`` and the crossing (the plane is the same), so the filter loses nothing.
3. **Binning** (:mod:`wsoft.accel.dcs_bins`). No hardware rasterizer: a light view fitted to the
   receivers (``grid_size`` cells per side) and, per potential edge, the conservative
   rectangle of cells its wedge can reach (the edge's projection widened by the light's extent at
   the receivers' depths, as :func:`~wsoft.lightspace.fit.fit_light_view` widens windows for soft
   casters); the (cell, edge) pairs are sorted into per-cell lists. Each receiver *gathers*: it
   tests only the edges listed in its own cell and writes only its own result (no atomics, no
   per-chunk count buffers: Warp's CPU atomics are not thread-safe across the thread pool, and a
   gather needs none). Receivers outside the view read a list of every edge (correct, slower).
   Cost: the receivers times the edges of their cells, not pixels times edges. A large light over
   many small casters makes every footprint wide and the lists quadratic in the grid's size: the
   grid is halved until they hold at most 8M pairs (:data:`~wsoft.accel.dcs_bins.MAX_PAIRS`;
   ``grid_size`` in the counters). Per receiver, an edge of its cell is skipped unless the plane
   ``o, a, b`` cuts the light's bound (``o`` inside the edge's wedge), part of the edge lies in
   front of the receiver's tangent plane, and it is a silhouette from ``o``; only then are the
   samples walked.
4. **STSV** (only when the light's casters hold perforated triangles not wholly behind a rect or
   disk light; ``wsoft plan`` shows the ``dcs_stsv`` pass then and not otherwise). Per perforated
   triangle both conservative volumes of §6 (:func:`~wsoft.accel.stsv.stsv_planes`, one per lit side of its plane), binned like
   the edges; a receiver inside either volume looks up every sample
   (:func:`~wsoft.accel.stsv.sample_blocked`: the crossing of eq. 1 and the alpha texture of
   eq. 5) and adds 1 where it is blocked. With ``transmittance=alpha`` (the paper's general case
   of a spatially varying transmittance) the perforated triangles do not count: each sample
   carries the product of ``1 - alpha`` over the triangles it crosses
   (:func:`~wsoft.accel.stsv.sample_transmittance`), and V sums those shares over the samples
   with ``count = 0``.

5. **V.** ``estimator=v_coef`` (the default, the paper's physically plausible ``v_coef``): the
   fraction of samples with ``count = 0``. ``estimator=direct``, the paper's Monte-Carlo
   direct-lighting variant: each sample weighted by its share of the receiver's unshadowed
   irradiance (receiver cosine times light cosine over squared distance, for samples spread over
   the light's area; the receiver cosine alone for a distant light's, spread by solid angle), V
   the weighted fraction, so that V times the unshadowed irradiance is the Monte-Carlo estimate of
   the direct lighting. It differs from ``v_coef`` where the light is large and close (a 4 x 4
   light at height 1 half hidden: 0.17 on average, ``tests/test_dcs.py``); the reference's V is
   the unweighted fraction.

Lights: rect, disk, sphere, cylinder (its silhouette rectangle, sampled as the reference samples it;
a line light its segment) and distant. A point light has no area: every sample is its centre and
depth complexity sampling degenerates to a hard shadow (``hard`` or ``izb``). UsdLux's
``collection:shadowLink`` is honoured (the excluded prims are neither edges, BVH nor volumes);
``inputs:shadow:distance`` is refused (the counts run to the light). Instanced stages are
flattened: the edges come from the soup's adjacency.

Counters (``stats["counters"]["techniques"]["dcs"][light]``): ``potential_edges``,
``wedge_tests`` (receiver-edge pairs read from the cells' lists), ``wedge_receivers`` (of those,
receivers inside a silhouette's wedge: the samples walked), ``perforated_triangles``,
``stsv_tests`` (receiver-volume tests), ``grid_size``, ``grid_bytes`` (cells and lists),
``edge_bin_pairs``, ``edges_in_every_cell`` (edges reaching into the light's bound), and the
``stsv_`` grid's own.

Example::

    frame = wsoft.render(scene, "dcs", width=640, height=480, samples=16)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.dcs_bins import BinsGPU, receiver_items
from wsoft.accel.occluders import count_crossings, in_wedge, side
from wsoft.lightspace.light import LightGPU, disk_shaped, is_round, light_bound, light_point, lit_along, silhouette_ellipse, silhouette_rect
from wsoft.lightspace.samples import LightSamples, sample_coords
from wsoft.accel.stsv import in_volume, light_ball, planes_t, receiver_matrix, s_triangle, sample_blocked, sample_transmittance
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.raster.shadow_rays import receiver_begin
from wsoft.scene.adjacency import silhouette_candidates
from wsoft.scene.surfaces import Surfaces
from wsoft.techniques._object_based import ObjectBased, ObjectBasedParams, object_based_passes
from wsoft.techniques.base import Quality, Tolerance, check, param

MAX_SAMPLES = 64
ESTIMATORS = ("v_coef", "direct")
TRANSMITTANCES = ("binary", "alpha")
counts_t = wp.types.vector(length=MAX_SAMPLES, dtype=wp.int32)
shares_t = wp.types.vector(length=MAX_SAMPLES, dtype=wp.float32)
points_t = wp.types.matrix(shape=(MAX_SAMPLES, 3), dtype=wp.float32)
BLOCKED = wp.constant(1 << 20)  # a sample behind the receiver's tangent plane


@dataclass(frozen=True)
class DCSParams(ObjectBasedParams):
    samples: int = param(16, "light samples per receiver (the paper: 16 or 64)", range=(1, MAX_SAMPLES))
    estimator: str = param("v_coef", "v_coef: V is the fraction of samples with no occluder (the paper's physically plausible "
                                     "v_coef); direct: the Monte-Carlo direct-lighting variant, each sample weighted by its "
                                     "unshadowed irradiance (cosines over squared distance), V the fraction of that irradiance "
                                     "that arrives")
    transmittance: str = param("binary", "perforated triangles: binary (a sample is hidden where the texture's alpha reaches the "
                                         "material's opacityThreshold: the paper's implementation) or alpha (each crossing lets "
                                         "1 - alpha of the sample through, the threshold unused: the paper's general case)")

    def __post_init__(self):
        super().__post_init__()
        check(self.estimator in ESTIMATORS, f"estimator {self.estimator!r} is not one of {', '.join(ESTIMATORS)}")
        check(self.transmittance in TRANSMITTANCES, f"transmittance {self.transmittance!r} is not one of {', '.join(TRANSMITTANCES)}")


# --------------------------------------------------------------------------- kernels


@wp.kernel
def dcs_visibility(
    offset: int,
    gb: GBufferGPU,
    ls: LightSamples,
    light: LightGPU,
    has_opaque: int,
    bvh: wp.uint64,
    tri_pts: wp.array[wp.vec3],
    ebins: BinsGPU,
    edge_pts: wp.array2d[wp.vec3],
    edge_faces: wp.array[wp.int32],
    has_stsv: int,
    tbins: BinsGPU,
    stri: wp.array[wp.int32],
    planes: wp.array2d[planes_t],
    cut: Surfaces,
    cut_pts: wp.array[wp.vec3],
    direct: int,
    alpha_mode: int,
    # outputs
    vis: wp.array[float],
    wedge_tests: wp.array[wp.int32],
    wedge_hits: wp.array[wp.int32],
    volume_tests: wp.array[wp.int32],
):
    """Per receiver: the depth complexity of each light sample (module docstring) and V (the
    fraction of samples with none, or with ``direct`` the irradiance-weighted fraction). With
    ``alpha_mode`` the perforated triangles do not count: each sample's share is the product of
    their transmittances, and a sample with no opaque occluder adds its share."""
    i = wp.tid() + offset
    wedge_tests[i] = 0
    wedge_hits[i] = 0
    volume_tests[i] = 0
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    p = gb.pos[i]
    nrm = gb.nrm[i]
    off, o, state, base, rot = receiver_begin(gb, ls, i)
    S = ls.count
    cnt = counts_t()
    share = shares_t()
    xs = points_t()
    first_front = int(-1)
    for s in range(S):
        c2, state = sample_coords(ls, state, base, rot, s)
        r = light_point(light, p, c2)
        d = wp.vec3(r[0], r[1], r[2])
        x = o + d * wp.max(r[3] - off, 0.0)
        xs[s] = x
        share[s] = 1.0
        if lit_along(light, nrm, d):
            cnt[s] = 0
            if first_front < 0:
                first_front = s
        else:
            cnt[s] = BLOCKED
    if first_front < 0:
        vis[i] = 0.0
        return
    # the reference point: the light's centre, or the first sample in front of the tangent plane
    rc = light_point(light, p, wp.vec2(0.0, 0.0))
    dc = wp.vec3(rc[0], rc[1], rc[2])
    xr = o + dc * wp.max(rc[3] - off, 0.0)
    if not lit_along(light, nrm, dc):
        xr = xs[first_front]
    base_count = int(0)
    if has_opaque != 0:
        dr = xr - o
        lr = wp.length(dr)
        if lr > 0.0:
            base_count = count_crossings(bvh, tri_pts, o, dr / lr, lr)
        # silhouette edges of the receiver's cell; sweep[s]: the normal of the swept plane o, r, s
        sweep = points_t()
        for s in range(S):
            sweep[s] = wp.cross(xr - o, xs[s] - o)
        ball = light_ball(light)
        distant = int(light.kind == 3)
        span = receiver_items(ebins, o)
        e0 = span[0]
        e1 = span[1]
        wedge_tests[i] = e1 - e0
        holding = int(0)
        for k in range(e0, e1):
            e = ebins.items[k]
            A = edge_pts[e, 0] - o
            B = edge_pts[e, 1] - o
            # is any of the edge in front of the receiver (samples behind are blocked anyway)?
            if wp.dot(nrm, A) <= 0.0 and wp.dot(nrm, B) <= 0.0:
                continue
            ne = wp.cross(A, B)
            nn = wp.dot(ne, ne)
            if not in_wedge(ne, nn, ball, distant, o):
                continue
            sigma = side(wp.dot(ne, edge_pts[e, 2] - o))
            if edge_faces[e] > 1:
                sigma += side(wp.dot(ne, edge_pts[e, 3] - o))
            hr = wp.dot(ne, xr - o)
            if sigma != 0:
                holding += 1
                for s in range(S):
                    x = xs[s]
                    hs = wp.dot(ne, x - o)
                    if (hs > 0.0) != (hr > 0.0):  # r and s on opposite sides of the plane o, a, b
                        # a and b on opposite sides of the swept plane o, r, s: each corner's side is
                        # computed alike for every edge it ends, so a sweep past a vertex is counted once
                        ns = sweep[s]
                        if (wp.dot(ns, A) > 0.0) != (wp.dot(ns, B) > 0.0):
                            # the crossing lies before the light: m - o = alpha A + beta B, alpha + beta >= 1
                            m = xr + (x - xr) * (hr / (hr - hs)) - o
                            if wp.dot(wp.cross(m, B - A), ne) >= nn:
                                sg = int(-1)
                                if hs > 0.0:
                                    sg = 1
                                cnt[s] = cnt[s] + sigma * sg
        wedge_hits[i] = holding
    if has_stsv != 0:
        span = receiver_items(tbins, o)
        t0 = span[0]
        t1 = span[1]
        nt = int(0)
        for k in range(t0, t1):
            j = tbins.items[k]
            nt += 1
            if in_volume(planes[j, 0], o, 0.0) or in_volume(planes[j, 1], o, 0.0):
                tri = stri[j]
                st = s_triangle(cut_pts[3 * j], cut_pts[3 * j + 1], cut_pts[3 * j + 2],
                                cut.tri_uv[3 * tri], cut.tri_uv[3 * tri + 1], cut.tri_uv[3 * tri + 2])
                J = receiver_matrix(st, o)
                for s in range(S):
                    if alpha_mode != 0:
                        share[s] = share[s] * sample_transmittance(cut, tri, st, J, o, xs[s])
                    elif sample_blocked(cut, tri, st, J, o, xs[s]):
                        cnt[s] = cnt[s] + 1
        volume_tests[i] = nt
    if direct == 0:
        visible = int(0)
        shared = float(0.0)
        for s in range(S):
            if cnt[s] != BLOCKED and base_count + cnt[s] <= 0:
                visible += 1
                shared += share[s]
        vis[i] = float(visible) / float(S)
        if alpha_mode != 0:
            vis[i] = shared / float(S)
    else:
        # the Monte-Carlo direct-lighting estimator: each sample weighted by its share of the
        # unshadowed irradiance (receiver cosine x light cosine / distance^2, as the samples are
        # spread over the light's area; a distant light's are spread by solid angle: cosine alone)
        lit = float(0.0)
        total = float(0.0)
        axis = light.az
        if light.kind == 2:
            axis = wp.normalize(light.position - p)
            if not is_round(light):  # an ellipsoid: the normal of the silhouette ellipse's plane, away from p
                ce, eu, ev, ext = silhouette_ellipse(light, p)
                axis = wp.normalize(wp.cross(eu, ev))
                if wp.dot(axis, ce - p) < 0.0:
                    axis = -axis
        elif light.kind == 5:  # a cylinder: the normal of its silhouette rectangle's plane, away from p
            ce, eu, ev, ext = silhouette_rect(light, p)
            axis = wp.normalize(wp.cross(eu, ev))
            if wp.dot(axis, ce - p) < 0.0:
                axis = -axis
        for s in range(S):
            dv = xs[s] - o
            dist = wp.length(dv)
            if dist > 0.0:
                d = dv / dist
                w = wp.max(wp.dot(nrm, d), 0.0)
                if light.kind != 3:
                    w = w * wp.max(wp.dot(d, axis), 0.0) / (dist * dist)
                total += w
                if cnt[s] != BLOCKED and base_count + cnt[s] <= 0:
                    lit += w * share[s]
        vis[i] = 0.0
        if total > 0.0:
            vis[i] = lit / total


# --------------------------------------------------------------------------- host


class DCS(ObjectBased):
    """Depth complexity sampling: per receiver and light sample, the occluder layers crossed (one
    ray to the light's centre plus silhouette-edge updates), soft textured shadow volumes for
    perforated triangles; V = the fraction of samples with none."""

    name = "dcs"
    distant_angle_limit = 50.0  # max point error 0.052 at 50 degrees, 0.115 at 60
    summary = ("depth complexity sampling: exact per-sample occluder counts from one ray per pixel and silhouette-edge "
               "updates, soft textured shadow volumes for perforated triangles")
    Params = DCSParams
    final_stage = "count"
    passes = object_based_passes("dcs", final_stage)
    quality = (Quality("samples", (4, 16, 64), "more light samples: noise down as with the reference, time up about linearly"),)
    tolerance = Tolerance(mae=0.003, mae_penumbra=0.075)  # measured 0.0015, 0.060 (16 rotated stratified samples)
    horizon = "exact"  # per light sample, as the reference
    distance_refusal = "the depth complexity counts every occluder between the receiver and the light"
    instancing_refusal = "its edges come from the flattened soup's adjacency and its reference rays walk the soup's BVH"
    point_refusal = "a point light has no area: depth complexity sampling needs light samples spread over it (use hard or izb)"
    cylinder_model = "its silhouette rectangle seen from each receiver, sampled as the reference samples it (a line light: its segment)"

    def edges(self, scene, opaque, light, device):
        """The potential silhouette edges of the light's bound, with both faces' far corners."""
        pts, nf = silhouette_candidates(scene, opaque, *light_bound(light))
        arrays = {"edge_pts": wp.array(pts.reshape(-1, 4, 3) if len(pts) else np.zeros((1, 4, 3), np.float32), dtype=wp.vec3, device=device),
                  "edge_faces": wp.array(nf if len(nf) else np.zeros(1, np.int32), dtype=wp.int32, device=device)}
        corners = pts[:, :2] if len(pts) else np.zeros((0, 2, 3), np.float32)
        return corners, arrays, {"potential_edges": int(len(pts))}

    def visibility(self, ctx, light, gb, ds, prep, st):
        p = self.params
        a = prep.data
        dev = ctx.device
        n = gb.count
        if st is None:
            tb, stri, planes, cut_pts = a["ebins"].gpu, wp.zeros(1, dtype=wp.int32, device=dev), wp.zeros((1, 2), dtype=planes_t, device=dev), a["tri_pts"]
        else:
            tb, stri, planes, cut_pts = st.data["tbins"].gpu, st.data["stri"], st.data["planes"], st.data["cut_pts"]
        vis = wp.empty(n, dtype=float, device=dev)
        wt = wp.empty(n, dtype=wp.int32, device=dev)
        vt = wp.empty(n, dtype=wp.int32, device=dev)
        wh = wp.empty(n, dtype=wp.int32, device=dev)
        bvh_id = a["bvh"].id if a["bvh"] is not None else wp.uint64(0)
        launch_chunked(
            dcs_visibility, n,
            inputs=[gb.gpu(), p.sample_pattern().on(dev, disk_shaped(light)), ctx.light_gpu(light),
                    a["has_opaque"], bvh_id, a["tri_pts"], a["ebins"].gpu, a["edge_pts"], a["edge_faces"], int(st is not None), tb, stri,
                    planes, ds.cutouts, cut_pts, int(p.estimator == "direct"), int(p.transmittance == "alpha")],
            outputs=[vis, wt, wh, vt], device=dev, min_chunk=256, per_thread=32)
        counters = {"wedge_tests": int(wt.numpy().astype(np.int64).sum()), "wedge_receivers": int(wh.numpy().astype(np.int64).sum()),
                    "stsv_tests": int(vt.numpy().astype(np.int64).sum())}
        return vis, counters
