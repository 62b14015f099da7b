"""``pwedge``: penumbra wedges (Akenine-Möller and Assarsson 2002; Assarsson and Akenine-Möller
2003) for opaque casters, with soft textured shadow volumes for perforated triangles (Forest,
Barthe, Guennebaud and Paulin 2009, §3.1, Algorithm 2 lines 12-15).

Per receiver ``o`` (a G-buffer sample, moved off its surface as the reference's shadow rays are):

1. **Hard shadow from the light's centre** (the shadow volume's stencil count). One segment from
   ``o`` to the centre ``c`` through a BVH of the light's opaque casters
   (:func:`~wsoft.accel.occluders.count_parts`): the covered fraction starts at the number of
   parts it crosses (a part: a connected piece of mesh, :func:`~wsoft.scene.adjacency.triangle_parts`;
   a closed box crossed through two faces counts once, two boxes one behind the other twice).
2. **Silhouette edges from the centre** (``pwedge_edges``, per light). The welded adjacency of
   each prim (:mod:`wsoft.scene.adjacency`: USD meshes split vertices at seams, so edges are
   matched by position); an edge is a silhouette when its two faces lie on one side of the plane
   through ``c`` and the edge, and open edges always are. Each keeps the plane of its hard shadow
   quad, oriented toward its faces (its *inner* side). A distant light's centre is its direction.
3. **Wedges** (``pwedge``). For each silhouette edge whose wedge holds ``o`` (the plane through
   ``o`` and the edge cuts the light's bound), the edge projected from ``o`` onto the light and
   clipped to it changes the covered fraction by the area of the light beyond it as seen from
   ``c`` (:mod:`wsoft.lightspace.coverage`, exact for rect, disk and elliptical lights): added when ``o`` is
   outside the edge's hard shadow quad, subtracted inside. This is the papers' per-wedge pixel
   shader with the coverage computed analytically instead of read from a 4D texture.
4. **STSV** (``pwedge_stsv``, only when the light's casters hold perforated triangles not wholly
   behind a rect or disk light; ``wsoft plan`` shows it). Per perforated triangle both volumes
   of §6, binned by cell; each receiver inside one looks up every light sample (eq. 1-5,
   :func:`~wsoft.accel.stsv.sample_blocked`) and ORs the blocked ones into its *LS_buffer* mask: ``samples`` bits per pixel, exactly
   ``samples x pixels`` bits in all (``ls_buffer_bytes`` in the counters), light samples from the
   shared generator (16 or 64 in the paper; any multiple of 8 up to 64 here).
5. ``V = F - clamp(covered + popcount(LS_buffer) / samples, 0, F)`` (``add_v_coef``), ``F`` the
   fraction of the light in front of the receiver's tangent plane.

**The light clipped to the receiver's half-space.** Only the part of the light in front of the
receiver's tangent plane lights it (the reference's rule, :mod:`wsoft.lightspace.halfspace`): where
the plane crosses the light (a wall under a wider ceiling light) every term is taken over that part
alone: the centre's count times ``F`` (exact analytic area for rect, disk, elliptical, sphere,
cylinder and distant lights), each edge's ``R`` clipped to the plane's line on the light
(:func:`~wsoft.lightspace.coverage.edge_coverage`), and only the LS_buffer's samples in front
count. V is normalised by the whole light, as the reference's.

**What it gets wrong, on purpose.** The sum counts coverage, not its union: where two occluders'
penumbrae overlap on the light, the overlap is counted twice and the point is *over-shadowed*
(Forest et al. Fig. 4(a), kept here; ``tests/test_pwedge.py`` measures it against the exact
answer, and ``wsoft bench stsv`` shows it). Counting every part over the centre keeps the umbra
where the centre is hidden by two occluders (a count of 0 or 1 there lets each edge uncover its own
part: two overlapping boxes' shadows lit up to 0.53 on 229 of 160 x 120 pixels where the truth is
0; with the count, 11 pixels on a box's top, at most 0.11). The silhouette is the centre's, not the
receiver's (the single-silhouette approximation): a face the centre sees edge-on leaves a strip up
to 0.4 too light beside it. Perforated triangles' bits are
added to the wedges' coverage, not merged with it, so a cutout over an opaque caster's penumbra is
over-shadowed too (Fig. 4(a)'s fence). ``dcs`` counts per light sample and has neither artifact.

No hardware rasterizer: wedges and volumes are binned into a light-space grid fitted to the
receivers (:mod:`wsoft.accel.dcs_bins`, ``grid_size`` cells per side) and each receiver
gathers the ones of its cell, writing only its own result (no atomics: Warp's CPU atomics are
not thread-safe across the thread pool). A scan conversion of wedge polygons into screen tiles
would do the same tests on more pixels: a wedge's screen footprint bounds its receivers loosely
where the wedge grazes a surface.

Lights: rect, disk (an elliptical one too), sphere (its silhouette disk; an ellipsoid's silhouette
ellipse), cylinder (its silhouette rectangle seen from the receiver, the reference's; a line light as
a rectangle :data:`~wsoft.lightspace.light.LINE_WIDTH` of its length wide) and distant (its cone as the disk it cuts at unit distance). A point light has no penumbra
(use ``hard`` or ``izb``). The receiver's own horizon caps ``V`` by the part of the light in front
of its tangent plane that emits toward it (``horizon = "fraction"``; the clipped integrals give no
more).
``collection:shadowLink`` is honoured; ``inputs:shadow:distance`` is refused. Instanced stages are
flattened. A shaped light (``UsdLux.ShapingAPI``) with a cone up to 90 degrees keeps only the
silhouette edges that meet its cone widened by the light (:func:`~wsoft.lightspace.light.cone_meets_balls`),
and the receivers its cone does not reach test no wedge.

Counters (``stats["counters"]["techniques"]["pwedge"][light]``): ``silhouette_edges``,
``wedge_tests`` (receiver-edge pairs read from the cells' lists), ``wedge_receivers`` (receivers
inside at least one wedge), ``wedge_hits`` (receiver-edge pairs whose edge covered part of the
light), ``clamped`` (receivers whose summed coverage went past the front fraction F or below 0: overlapping
silhouettes at work), ``perforated_triangles``, ``stsv_tests``, ``ls_buffer_bytes``, ``grid_size`` and the
bins' sizes.

Example::

    frame = wsoft.render(scene, "pwedge", width=640, height=480)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.dcs_bins import BinsGPU, receiver_items
from wsoft.accel.occluders import count_parts, in_wedge
from wsoft.lightspace.bitmask import popcount
from wsoft.lightspace.coverage import edge_coverage, front_coverage, light_frame, receiver_front
from wsoft.lightspace.light import LightGPU, cone_meets_balls, disk_shaped, in_front, light_bound, light_point, light_reaches
from wsoft.lightspace.samples import LightSamples, sample_coords
from wsoft.accel.stsv import in_volume, light_ball, planes_t, receiver_matrix, s_triangle, sample_blocked
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.raster.shadow_rays import ray_offset, ray_origin, receiver_begin
from wsoft.scene.adjacency import silhouette_candidates, triangle_parts
from wsoft.scene.surfaces import Surfaces
from wsoft.techniques._object_based import ObjectBased, ObjectBasedParams, object_based_passes
from wsoft.techniques.base import Quality, Tolerance, check, param

MAX_SAMPLES = 64
points_t = wp.types.matrix(shape=(MAX_SAMPLES, 3), dtype=wp.float32)


@dataclass(frozen=True)
class PWedgeParams(ObjectBasedParams):
    samples: int = param(16, "light samples of the perforated triangles' LS_buffer (bits per pixel; the paper: 16 or 64; a "
                             "multiple of 8)", range=(8, MAX_SAMPLES))

    def check_samples(self) -> None:
        check(self.samples % 8 == 0, f"samples must be a multiple of 8 (the LS_buffer holds whole bytes), not {self.samples}")


# --------------------------------------------------------------------------- kernels


@wp.kernel
def ls_buffer_pass(
    offset: int,
    gb: GBufferGPU,
    ls: LightSamples,
    light: LightGPU,
    tbins: BinsGPU,
    stri: wp.array[wp.int32],
    planes: wp.array2d[planes_t],
    cut: Surfaces,
    cut_pts: wp.array[wp.vec3],
    nbytes: int,
    # outputs
    ls_buffer: wp.array[wp.uint8],
    volume_tests: wp.array[wp.int32],
):
    """Receiver ``i``'s LS_buffer: bit ``s`` set when a perforated triangle whose volume holds the
    receiver blocks light sample ``s`` at its alpha texture (the OR over S-triangles)."""
    i = wp.tid() + offset
    volume_tests[i] = 0
    lo = wp.uint32(0)
    hi = wp.uint32(0)
    if gb_covered(gb, i):
        p = gb.pos[i]
        n = gb.nrm[i]
        off, o, state, base, rot = receiver_begin(gb, ls, i)
        S = ls.count
        xs = points_t()
        have_points = int(0)
        span = receiver_items(tbins, o)
        t0 = span[0]
        t1 = span[1]
        volume_tests[i] = t1 - t0
        for k in range(t0, t1):
            j = tbins.items[k]
            if in_volume(planes[j, 0], o, 0.0) or in_volume(planes[j, 1], o, 0.0):
                if have_points == 0:  # the light points, once, for receivers inside some volume only
                    for s in range(S):
                        c2, state = sample_coords(ls, state, base, rot, s)
                        r = light_point(light, p, c2)
                        xs[s] = o + wp.vec3(r[0], r[1], r[2]) * wp.max(r[3] - off, 0.0)
                    have_points = 1
                tri = stri[j]
                st = s_triangle(cut_pts[3 * j], cut_pts[3 * j + 1], cut_pts[3 * j + 2],
                                cut.tri_uv[3 * tri], cut.tri_uv[3 * tri + 1], cut.tri_uv[3 * tri + 2])
                J = receiver_matrix(st, o)
                for s in range(S):
                    if in_front(n, xs[s] - p) and sample_blocked(cut, tri, st, J, o, xs[s]):
                        if s < 32:
                            lo = lo | (wp.uint32(1) << wp.uint32(s))
                        else:
                            hi = hi | (wp.uint32(1) << wp.uint32(s - 32))
    for b in range(nbytes):
        w = lo
        if b >= 4:
            w = hi
        ls_buffer[i * nbytes + b] = wp.uint8((w >> wp.uint32(8 * (b % 4))) & wp.uint32(255))


@wp.kernel
def pwedge_visibility(
    offset: int,
    gb: GBufferGPU,
    light: LightGPU,
    has_opaque: int,
    bvh: wp.uint64,
    tri_pts: wp.array[wp.vec3],
    tri_part: wp.array[wp.int32],
    ebins: BinsGPU,
    edge_pts: wp.array2d[wp.vec3],
    edge_quad: wp.array[wp.vec3],
    has_stsv: int,
    ls_buffer: wp.array[wp.uint8],
    nbytes: int,
    samples: int,
    # outputs
    vis: wp.array[float],
    wedge_tests: wp.array[wp.int32],
    wedge_hits: wp.array[wp.int32],
    clamped: wp.array[wp.int32],
):
    """Per receiver: the hard shadow from the centre, the wedges' signed coverages, the LS_buffer's
    bits (module docstring) and V."""
    i = wp.tid() + offset
    wedge_tests[i] = 0
    wedge_hits[i] = 0
    clamped[i] = 0
    if not gb_covered(gb, i) or not light_reaches(light, gb.pos[i]):  # outside a shaped light's cone: masked, no shadow
        vis[i] = 1.0
        return
    p = gb.pos[i]
    nrm = gb.nrm[i]
    off = ray_offset(p, gb.err[i])
    o = ray_origin(p, nrm, off)
    cov = float(0.0)
    c, u, v, ext, disk, smax = light_frame(light, o)
    # the light clipped to the receiver's front half-space: only that part can light it
    front_line = receiver_front(c, u, v, ext, disk, nrm, wp.where(light.kind == 3, o, p))
    front = front_coverage(ext, disk, front_line)
    if has_opaque != 0:
        rc = light_point(light, p, wp.vec2(0.0, 0.0))
        dc = wp.vec3(rc[0], rc[1], rc[2])
        tm = wp.max(rc[3] - off, 0.0)
        if tm > 0.0:
            cov = front * float(count_parts(bvh, tri_pts, tri_part, o, dc, tm))  # the stencil count: one per part over the centre
        ball = light_ball(light)
        distant = int(light.kind == 3)
        span = receiver_items(ebins, o)
        e0 = span[0]
        e1 = span[1]
        wedge_tests[i] = e1 - e0
        hits = int(0)
        for k in range(e0, e1):
            e = ebins.items[k]
            a = edge_pts[e, 0]
            b = edge_pts[e, 1]
            ne = wp.cross(a - o, b - o)
            nn = wp.dot(ne, ne)
            if not in_wedge(ne, nn, ball, distant, o):
                continue
            f = edge_coverage(c, u, v, ext, disk, smax, o, a, b, front_line)
            if f > 0.0:
                hits += 1
                if wp.dot(edge_quad[e], o - a) > 0.0:
                    cov -= f  # inside the edge's hard shadow quad: the part beyond the edge is uncovered
                else:
                    cov += f
        wedge_hits[i] = hits
    if has_stsv != 0:
        bits = int(0)
        for kb in range(nbytes):
            bits += popcount(wp.uint32(ls_buffer[i * nbytes + kb]))
        cov += float(bits) / float(samples)
    if cov > front or cov < 0.0:
        clamped[i] = 1
    vis[i] = front - wp.clamp(cov, 0.0, front)


# --------------------------------------------------------------------------- host


def centre_silhouettes(scene, opaque: np.ndarray, light) -> tuple[np.ndarray, np.ndarray]:
    """The silhouette edges of the opaque casters seen from ``light``'s centre (its direction for a
    distant light): corners [E, 2, 3] float32 and the normal of each edge's hard shadow quad [E, 3]
    float32 (the plane through the centre and the edge), pointing to the side its faces lie on."""
    c, _, distant = light_bound(light)
    pts, nf = silhouette_candidates(scene, opaque, c, 0.0, distant)
    if not len(pts):
        return np.zeros((0, 2, 3), np.float32), np.zeros((0, 3), np.float32)
    P = pts.astype(np.float64)
    a, b = P[:, 0], P[:, 1]
    apex = -np.broadcast_to(c, a.shape) if distant else a - c  # a - (a + K d) ~ -d for a distant light
    n = np.cross(apex, b - a)
    s0 = np.sign(np.einsum("ij,ij->i", n, P[:, 2] - a))
    s1 = np.where(nf > 1, np.sign(np.einsum("ij,ij->i", n, P[:, 3] - a)), 0.0)
    w = np.sign(s0 + s1)
    ln = np.linalg.norm(n, axis=1)
    keep = (w != 0) & (ln > 0) & np.isfinite(ln)
    quad = (n[keep] * (w[keep] / ln[keep])[:, None]).astype(np.float32)
    return pts[keep, :2].astype(np.float32), quad


class PWedge(ObjectBased):
    """Penumbra wedges: the hard shadow from the light's centre corrected, per silhouette edge whose
    wedge holds the receiver, by the light area the edge covers; perforated triangles through
    soft textured shadow volumes into an LS_buffer bitmask whose bits are added."""

    name = "pwedge"
    distant_angle_limit = 80.0  # max point error 0.095 at 80 degrees, 0.116 at 90
    summary = ("penumbra wedges: hard shadow from the light's centre plus each silhouette edge's covered light area "
               "(over-shadows where silhouettes overlap); soft textured shadow volumes into an LS_buffer for perforated triangles")
    Params = PWedgeParams
    final_stage = "wedges"
    passes = object_based_passes("pwedge", final_stage)
    quality = (Quality("samples", (8, 16, 64), "more LS_buffer samples: noise of perforated triangles' shadows down, time up"),)
    tolerance = Tolerance(mae=0.0003, mae_penumbra=0.01)  # measured 1.3e-5, 0.0005: exact for one convex occluder, up to float
    distance_refusal = "its hard shadow and wedges run from the receiver to the light"
    instancing_refusal = "its edges come from the flattened soup's adjacency and its centre rays walk the soup's BVH"
    point_refusal = "a point light has no penumbra: penumbra wedges need an area (use hard or izb)"
    cylinder_model = ("its silhouette rectangle seen from each receiver, its covered area exact as a rect light's (a line light: a rectangle "
                      "1e-3 of its length wide)")

    def edges(self, scene, opaque, light, device):
        """The silhouette edges seen from the light's centre, with their hard shadow quads' planes;
        of a shaped light's (a cone up to 90 degrees) only those that meet its cone widened by the
        light (:func:`~wsoft.lightspace.light.cone_meets_balls`: an edge outside it shadows no
        receiver the cone reaches, whose wedges are the only ones read)."""
        pts, quad = centre_silhouettes(scene, opaque, light)
        if len(pts) and light.shaping.coned:
            keep = cone_meets_balls(light, pts.astype(np.float64).mean(axis=1), 0.5 * np.linalg.norm(pts[:, 1] - pts[:, 0], axis=1))
            pts, quad = pts[keep], quad[keep]
        part = triangle_parts(scene.points, scene.triangles[np.flatnonzero(opaque)])  # in opaque_bvh's order
        arrays = {"edge_pts": wp.array(pts if len(pts) else np.zeros((1, 2, 3), np.float32), dtype=wp.vec3, device=device),
                  "edge_quad": wp.array(quad if len(quad) else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device),
                  "tri_part": wp.array(part if len(part) else np.zeros(1, np.int32), dtype=wp.int32, device=device)}
        return pts, arrays, {"silhouette_edges": int(len(pts))}

    def perforated(self, ctx, light, gb, ds, counters, data):
        """The LS_buffer: per receiver, the light samples its perforated triangles block (one bit each)."""
        p = self.params
        dev = ctx.device
        nbytes = p.samples // 8
        n = gb.count
        buf = wp.empty(n * nbytes, dtype=wp.uint8, device=dev)
        vt = wp.empty(n, dtype=wp.int32, device=dev)
        launch_chunked(
            ls_buffer_pass, n,
            inputs=[gb.gpu(), p.sample_pattern().on(dev, disk_shaped(light)), ctx.light_gpu(light),
                    data["tbins"].gpu, data["stri"], data["planes"], ds.cutouts, data["cut_pts"], nbytes],
            outputs=[buf, vt], device=dev, min_chunk=256, per_thread=32)
        counters["stsv_tests"] = int(vt.numpy().astype(np.int64).sum())
        counters["ls_buffer_bytes"] = int(buf.size)
        return counters, {"ls_buffer": buf}

    def visibility(self, ctx, light, gb, ds, prep, st):
        p = self.params
        a = prep.data
        dev = ctx.device
        n = gb.count
        nbytes = p.samples // 8
        buf = st.data["ls_buffer"] if st is not None else wp.zeros(1, dtype=wp.uint8, device=dev)
        vis = wp.empty(n, dtype=float, device=dev)
        wt = wp.empty(n, dtype=wp.int32, device=dev)
        wh = wp.empty(n, dtype=wp.int32, device=dev)
        cl = wp.empty(n, dtype=wp.int32, device=dev)
        bvh_id = a["bvh"].id if a["bvh"] is not None else wp.uint64(0)
        launch_chunked(
            pwedge_visibility, n,
            inputs=[gb.gpu(), ctx.light_gpu(light), a["has_opaque"], bvh_id, a["tri_pts"], a["tri_part"], a["ebins"].gpu,
                    a["edge_pts"], a["edge_quad"], int(st is not None), buf, nbytes, p.samples],
            outputs=[vis, wt, wh, cl], device=dev, min_chunk=256, per_thread=32)
        whn = wh.numpy()
        counters = {"wedge_tests": int(wt.numpy().astype(np.int64).sum()), "wedge_receivers": int((whn > 0).sum()),
                    "wedge_hits": int(whn.astype(np.int64).sum()), "clamped": int(cl.numpy().sum())}
        return vis, counters
