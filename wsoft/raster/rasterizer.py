"""The rasterizer: one scan conversion of triangles into a view, many fragment actions.

:func:`make_rasterizer` builds a :class:`Rasterizer` for a projection (perspective or
orthographic), a *fragment* and two modes, specialised at code generation (``wp.static``, as
warp.fem builds its kernels): nothing unused is compiled in.

* **Fragment** — a ``@wp.func`` made with :func:`fragment`, called for every texel (or pixel)
  a triangle covers: ``f(target, x, y, z, bary, tri)`` with the target struct (its first
  argument's type, e.g. :class:`DepthTarget`), the texel, the interpolated linear view depth,
  the perspective-correct weights of the triangle's corners at the texel (zeros unless the
  fragment asks for them) and the triangle's index. A fragment may write only what belongs to
  its texel (the texel itself, or what is bucketed under it): that is what lets the scheduler
  share the map out by bands of rows. :func:`depth_min` (a depth map) and
  :func:`gated_depth_min` (Salzman's inverted depth test: only surfaces behind a gate map) are
  the two fragments here; an irregular z-buffer tests the eye samples of a cell, a shadow
  volume ORs bits into a pixel's mask.
* **conservative** — every texel a triangle touches (and those within
  :data:`CONSERVATIVE_MARGIN` of a texel's edge, so that rounding never drops one), with the
  nearest depth over the texel (clamped to the triangle's range), instead of the texel centres it
  covers. **inner** (with conservative) is its opposite: only texels the triangle covers whole
  (within the same margin), with the *farthest* depth over the texel, and never a cutout triangle
  (its holes may let light through): a map of depths that certainly block every ray of the texel.
* **alpha** — triangles with a cutout material are alpha-tested per texel (perspective-correct
  uv at the texel centre).

Every kernel projects (a whole mesh's points once each first, :func:`project_points`: a mesh has
about half as many points as triangles), culls the far faces of closed surfaces (exact, from
:class:`~wsoft.scene.device.Surfaces`), clips at a perspective view's near plane (one or two
triangles) and scan-converts (small boxes in one flat loop, branch-free for a *masked* fragment in
an orthographic view; wide triangles along exact spans of covered texel centres). Fragments deeper than the view's far depth (behind every receiver: they
can shadow nothing) are not emitted, so a huge or far triangle cannot flood a map with depths
that wreck its depth range. Scheduling (:meth:`Rasterizer.run`):

* **CUDA**: one launch over (bands of :data:`GPU_BAND_ROWS` rows) x triangles; fragments write
  with real atomics.
* **CPU**: Warp runs a launch on one thread and its atomics are plain read-modify-write, so no
  two concurrent launches may touch the same element. A fragment that can *merge* (its target
  has an order-independent combine, :class:`FragmentSpec`) is run as the old depth rasterizer
  was: each worker rasterizes interleaved chunks of triangles into a private target, the
  private targets are merged by disjoint ranges, then triangles larger than
  :data:`BIG_TRIANGLE_TEXELS` (a ground plane) or crossing the near plane go to a second pass
  split into disjoint bands of rows. Any other fragment runs in disjoint bands of rows only.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU, boxes_in_view, texel_of, view_of
from wsoft.parallel import cpu_threads, ensure_loaded, launch_chunked, run_tasks
from wsoft.scene.device import DeviceScene, face_surfaces, view_surfaces
from wsoft.scene.surfaces import CULL_SKIP, Surfaces, surface_present, without_culling

GPU_BAND_ROWS = 64  # CUDA: rows per band (one thread per triangle and band)
SMALL_BOX_TEXELS = 16  # triangles whose texel box is this small take the flat loop (orthographic views)
SMALL_BOX_TEXELS_PERSP = 8  # the same for perspective views, whose loop divides per covered texel
CPU_CHUNK = 32768  # CPU: triangles per launch; a worker's chunks are interleaved with the others'
CONSERVATIVE_MARGIN = wp.constant(1.0e-3)  # texels: conservative coverage reaches this far past a texel, against rounding
BIG_TRIANGLE_TEXELS = 4096  # CPU: triangles with a larger texel bounding box go to the banded pass
PRIVATE_BUDGET = 1 << 30  # CPU: bytes allowed for per-worker private targets
PERSPECTIVE = "perspective"
ORTHOGRAPHIC = "orthographic"


# --------------------------------------------------------------------------- fragments


@dataclass(frozen=True, eq=False)
class FragmentSpec:
    """What the scheduler knows of a fragment besides its code.

    ``private(target, device)`` makes a worker's private target (its writable arrays not yet
    cleared) and ``clear(private, device)`` clears it to the combine's identity; ``merge(privates,
    target, device)`` folds private targets into ``target`` by disjoint ranges. Without them
    (``None``) the fragment runs in disjoint bands of rows only. ``bary``: the fragment reads the
    corner weights (computed only then). ``masked``: a call with depth ``DEPTH_CLEAR`` changes
    nothing (a depth minimum), so a small triangle's flat loop calls it at every texel of its box,
    at ``DEPTH_CLEAR`` where the triangle does not cover the texel, without a branch per texel."""

    func: object
    target: type
    private: Callable | None = None
    clear: Callable | None = None
    merge: Callable | None = None
    bary: bool = False
    masked: bool = False

    @property
    def name(self) -> str:
        return self.func.key


FRAGMENTS: dict[str, FragmentSpec] = {}


def fragment(target: type, *, private=None, clear=None, merge=None, bary: bool = False, masked: bool = False):
    """Decorator: a ``@wp.func`` fragment ``f(target, x, y, z, bary, tri)`` registered with its
    :class:`FragmentSpec` (see :data:`FRAGMENTS`)."""

    def deco(f):
        func = wp.func(f)
        FRAGMENTS[func.key] = FragmentSpec(func, target, private, clear, merge, bary, masked)
        return func

    return deco


@wp.struct
class DepthTarget:
    """A depth map, ``[H, W]`` float32 linear view depth; ``DEPTH_CLEAR`` where empty."""

    depth: wp.array2d[float]


@wp.struct
class GatedDepthTarget:
    """A depth map written only behind ``gate`` (same shape): surfaces behind the casters."""

    depth: wp.array2d[float]
    gate: wp.array2d[float]


@wp.kernel
def fill_depth(
    offset: int,
    value: float,
    # outputs
    dst: wp.array[float],
):
    dst[wp.tid() + offset] = value


@wp.kernel
def merge_min(
    offset: int,
    src: wp.array[float],
    # outputs
    dst: wp.array[float],
):
    """dst = min(dst, src), element-wise over flat maps."""
    i = wp.tid() + offset
    dst[i] = wp.min(dst[i], src[i])


def _private_depth(t, device):
    ensure_loaded(fill_depth, device)  # cleared inside the workers' tasks
    p = type(t)()
    p.depth = wp.empty(t.depth.shape, dtype=float, device=device)
    if hasattr(t, "gate"):
        p.gate = t.gate
    return p


def _clear_depth(t, device):
    """Clear a private depth target (runs inside its worker's task: one thread)."""
    ensure_loaded(fill_depth, device)
    wp.launch(fill_depth, dim=t.depth.size, inputs=[0, DEPTH_CLEAR], outputs=[t.depth.reshape(-1)], device=device)


def _merge_depth(privates, t, device):
    flat = t.depth.reshape(-1)
    for p in privates:
        launch_chunked(merge_min, flat.shape[0], inputs=[p.depth.reshape(-1)], outputs=[flat], device=device, min_chunk=1 << 16)


@fragment(DepthTarget, private=_private_depth, clear=_clear_depth, merge=_merge_depth, masked=True)
def depth_min(t: DepthTarget, x: int, y: int, z: float, bary: wp.vec3, tri: int):
    """Keep the nearest depth of the texel."""
    wp.atomic_min(t.depth, y, x, z)


@fragment(GatedDepthTarget, private=_private_depth, clear=_clear_depth, merge=_merge_depth, masked=True)
def gated_depth_min(t: GatedDepthTarget, x: int, y: int, z: float, bary: wp.vec3, tri: int):
    """Keep the nearest depth behind the gate (the inverted depth test; nothing where the gate is empty)."""
    if z > t.gate[y, x] * 1.0001:
        wp.atomic_min(t.depth, y, x, z)


# --------------------------------------------------------------------------- shared geometry


@wp.func
def edge(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> float:
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


@wp.func
def span_limit(lim: wp.vec2, e: float, g: float, inv_g: float, pxr: float) -> wp.vec2:
    """Narrow the row span [lim.x, lim.y] (in texel x) to where e + g * (px - pxr) >= 0.

    Written with selects rather than branches: the sign of ``g`` is unpredictable from one
    row of one small triangle to the next."""
    t = pxr - e * inv_g
    lo = wp.max(lim[0], wp.where(g > 0.0, t, -1.0e30))
    hi = wp.min(lim[1], wp.where(g < 0.0, t, 1.0e30))
    hi = wp.where(g == 0.0 and e < 0.0, -1.0e30, hi)
    return wp.vec2(lo, hi)


@wp.func
def clip_point(p: wp.vec3, q: wp.vec3, near: float) -> wp.vec4:
    """Where segment p->q crosses the near plane: the point (xyz) and its parameter along p->q (w)."""
    s = (near - p[2]) / (q[2] - p[2])
    r = p + (q - p) * s
    return wp.vec4(r[0], r[1], r[2], s)


@wp.func
def corner_weights(l0: float, l1: float, l2: float, qa: float, qb: float, qc: float, persp: int,
                   wa: wp.vec3, wb: wp.vec3, wc: wp.vec3) -> wp.vec3:
    """Weights of the original triangle's corners at a texel from the (clipped) triangle's screen
    barycentrics: clamped to >= 0, perspective-corrected, normalised; zeros if all vanish."""
    c0 = wp.max(l0, 0.0)
    c1 = wp.max(l1, 0.0)
    c2 = wp.max(l2, 0.0)
    if persp != 0:  # perspective-correct weights
        c0 = c0 * qa
        c1 = c1 * qb
        c2 = c2 * qc
    s = c0 + c1 + c2
    if s > 0.0:
        return (wa * c0 + wb * c1 + wc * c2) / s
    return wp.vec3(0.0)


# --------------------------------------------------------------------------- the factory


def _make_raster_triangle(persp: bool, spec: FragmentSpec, conservative: bool, alpha: bool, inner: bool = False):
    """The scan conversion of one (clipped) triangle, specialised; calls the fragment per texel."""
    Target = spec.target
    frag = spec.func
    bary = spec.bary
    # masked calls of an orthographic view's small triangles; a perspective view's would divide at every
    # texel of the box (measured slower than branching on city's Rect light)
    masked = spec.masked and not bary and not persp
    small_box = SMALL_BOX_TEXELS_PERSP if persp else SMALL_BOX_TEXELS

    def raster_triangle(
        lv: ViewGPU,
        tri: int,
        ta: wp.vec2,
        tb: wp.vec2,
        tc: wp.vec2,
        za: float,
        zb: float,
        zc: float,
        wa: wp.vec3,
        wb: wp.vec3,
        wc: wp.vec3,
        row0: int,
        row1: int,
        cut: Surfaces,
        alpha_on: int,
        target: Target,
    ):
        # ta, tb, tc: corners in texel coordinates; za, zb, zc: their view depths; wa, wb, wc: the
        # corners' weights of the original triangle (uv of the alpha test, the fragment's bary)
        area = edge(ta[0], ta[1], tb[0], tb[1], tc[0], tc[1])
        if wp.abs(area) < 1.0e-12:
            return
        if wp.static(inner):
            if alpha_on != 0:  # a cutout may have a hole anywhere: it blocks no texel for certain
                return
        xmin = wp.min(ta[0], wp.min(tb[0], tc[0]))
        xmax = wp.max(ta[0], wp.max(tb[0], tc[0]))
        ymin = wp.min(ta[1], wp.min(tb[1], tc[1]))
        ymax = wp.max(ta[1], wp.max(tb[1], tc[1]))
        x0 = int(0)
        x1 = int(0)
        y0 = int(0)
        y1 = int(0)
        if wp.static(conservative):
            x0 = int(wp.floor(xmin - CONSERVATIVE_MARGIN))
            x1 = int(wp.floor(xmax + CONSERVATIVE_MARGIN))
            y0 = int(wp.floor(ymin - CONSERVATIVE_MARGIN))
            y1 = int(wp.floor(ymax + CONSERVATIVE_MARGIN))
        else:
            x0 = int(wp.ceil(xmin - 0.5))
            x1 = int(wp.floor(xmax - 0.5))
            y0 = int(wp.ceil(ymin - 0.5))
            y1 = int(wp.floor(ymax - 0.5))
        x0 = wp.max(x0, 0)
        x1 = wp.min(x1, lv.width - 1)
        # the box on the map (yb0..yb1) sets the path and the reference points: the same for every
        # band of rows, so values never depend on how the rows are shared out
        yb0 = wp.max(y0, 0)
        yb1 = wp.min(y1, lv.height - 1)
        y0 = wp.max(yb0, row0)
        y1 = wp.min(yb1, row1 - 1)
        if x0 > x1 or y0 > y1:  # covers no texel centre (most small triangles of a dense mesh)
            return
        inv_area = 1.0 / area
        # interpolated quantity: q = 1/z (perspective) or z (orthographic); both affine in texel space
        qa = za
        qb = zb
        qc = zc
        if wp.static(persp):
            qa = 1.0 / za
            qb = 1.0 / zb
            qc = 1.0 / zc
        # gradients of the barycentrics (l0 from edge b->c, l1 from c->a, l2 from a->b)
        g0x = -(tc[1] - tb[1]) * inv_area
        g0y = (tc[0] - tb[0]) * inv_area
        g1x = -(ta[1] - tc[1]) * inv_area
        g1y = (ta[0] - tc[0]) * inv_area
        g2x = -(tb[1] - ta[1]) * inv_area
        g2y = (tb[0] - ta[0]) * inv_area
        qx = g0x * qa + g1x * qb + g2x * qc
        qy = g0y * qa + g1y * qb + g2y * qc
        qmin = float(0.0)
        qmax = float(0.0)
        hx0 = float(0.0)
        hx1 = float(0.0)
        hx2 = float(0.0)
        if wp.static(conservative):
            qmin = wp.min(qa, wp.min(qb, qc))
            qmax = wp.max(qa, wp.max(qb, qc))
            hx0 = (0.5 + CONSERVATIVE_MARGIN) * (wp.abs(g0x) + wp.abs(g0y))
            hx1 = (0.5 + CONSERVATIVE_MARGIN) * (wp.abs(g1x) + wp.abs(g1y))
            hx2 = (0.5 + CONSERVATIVE_MARGIN) * (wp.abs(g2x) + wp.abs(g2y))
        nx = x1 - x0 + 1
        if wp.static(not conservative):
            if alpha_on == 0 and nx * (yb1 - yb0 + 1) <= wp.static(small_box):
                # a small triangle: test every texel centre of its box in one flat loop (fewer branches
                # than lines and spans); barycentrics and q from the box's first centre (no drift this small)
                pxb = float(x0) + 0.5
                pyb = float(yb0) + 0.5
                b0 = edge(tb[0], tb[1], tc[0], tc[1], pxb, pyb) * inv_area
                b1 = edge(tc[0], tc[1], ta[0], ta[1], pxb, pyb) * inv_area
                qb0 = b0 * qa + b1 * qb + (1.0 - b0 - b1) * qc
                dx = int(0)
                dy = y0 - yb0
                for _k in range(nx * (y1 - y0 + 1)):
                    fx = float(dx)
                    fy = float(dy)
                    l0 = b0 + g0x * fx + g0y * fy
                    l1 = b1 + g1x * fx + g1y * fy
                    if wp.static(masked):
                        # selects, not branches: whether a texel of a tiny triangle's box is covered is a coin
                        # toss (orthographic only: z is the plane itself, no division)
                        zm = qb0 + qx * fx + qy * fy
                        zm = wp.where(wp.min(wp.min(l0, l1), 1.0 - l0 - l1) >= 0.0, zm, DEPTH_CLEAR)
                        wp.static(frag)(target, x0 + dx, yb0 + dy, wp.where(zm <= lv.far, zm, DEPTH_CLEAR), wp.vec3(0.0), tri)
                    elif l0 >= 0.0 and l1 >= 0.0 and 1.0 - l0 - l1 >= 0.0:
                        z = qb0 + qx * fx + qy * fy
                        if wp.static(persp):
                            z = 1.0 / wp.max(z, 1.0e-30)
                        w = wp.vec3(0.0)
                        if wp.static(bary):
                            w = corner_weights(l0, l1, 1.0 - l0 - l1, qa, qb, qc, wp.static(int(persp)), wa, wb, wc)
                        if z <= lv.far:  # behind every receiver: shadows nothing
                            wp.static(frag)(target, x0 + dx, yb0 + dy, z, w, tri)
                    dx += 1
                    if dx == nx:
                        dx = 0
                        dy += 1
                return
        # plain case (no alpha test, not conservative): walk the exact span of covered texel
        # centres on each line and evaluate the depth plane directly at each texel. Lines run along
        # the bounding box's longer side (columns for a tall, thin triangle): fewer, longer spans.
        spans = wp.static(not conservative) and alpha_on == 0
        cols = spans and (yb1 - yb0) > (x1 - x0)
        o0 = y0
        o1 = y1
        n0 = x0  # the lines' reference texel (band-independent)
        n1 = x1
        nlo = x0  # the texels of each line inside this band
        nhi = x1
        h0 = g0x
        h1 = g1x
        h2 = g2x
        qn = qx
        if cols:
            o0 = x0
            o1 = x1
            n0 = yb0
            n1 = yb1
            nlo = y0
            nhi = y1
            h0 = g0y
            h1 = g1y
            h2 = g2y
            qn = qy
        # where each barycentric crosses zero along a line is pr - e / h: keep 1/h (0 when h = 0)
        i0 = float(0.0)
        i1 = float(0.0)
        i2 = float(0.0)
        if h0 != 0.0:
            i0 = 1.0 / h0
        if h1 != 0.0:
            i1 = 1.0 / h1
        if h2 != 0.0:
            i2 = 1.0 / h2
        for o in range(o0, o1 + 1):
            po = float(o) + 0.5
            pr = float(n0) + 0.5  # the line's first texel centre, along the line
            pxr = pr
            pyr = po
            if cols:
                pxr = po
                pyr = pr
            ns = nlo
            ne = nhi
            e0 = edge(tb[0], tb[1], tc[0], tc[1], pxr, pyr) * inv_area
            e1 = edge(tc[0], tc[1], ta[0], ta[1], pxr, pyr) * inv_area
            # q at the line's first texel centre from the barycentrics (stable even when corners are
            # far outside the map), then the plane's slope along the line from there
            q_row = e0 * qa + e1 * qb + (1.0 - e0 - e1) * qc
            if spans:
                lim = wp.vec2(float(n0) - 1.0, float(n1) + 2.0)
                lim = span_limit(lim, e0, h0, i0, pr)
                lim = span_limit(lim, e1, h1, i1, pr)
                lim = span_limit(lim, 1.0 - e0 - e1, h2, i2, pr)
                ns = wp.max(nlo, int(wp.ceil(lim[0] - 0.5)))
                ne = wp.min(nhi, int(wp.floor(lim[1] - 0.5)))
            for n in range(ns, ne + 1):
                x = n
                y = o
                if cols:
                    x = o
                    y = n
                px = float(x) + 0.5
                py = float(y) + 0.5
                covered = True
                q = q_row + qn * (float(n) + 0.5 - pr)
                w = wp.vec3(0.0)
                if not spans or wp.static(bary):
                    # evaluated per texel, not stepped: stepping drifts on wide triangles
                    l0 = edge(tb[0], tb[1], tc[0], tc[1], px, py) * inv_area
                    l1 = edge(tc[0], tc[1], ta[0], ta[1], px, py) * inv_area
                    l2 = 1.0 - l0 - l1
                    if not spans:
                        if wp.static(inner):
                            covered = l0 - hx0 >= 0.0 and l1 - hx1 >= 0.0 and l2 - hx2 >= 0.0
                            # farthest depth over the texel square (q = 1/z: the smallest q)
                            if wp.static(persp):
                                q = q - 0.5 * (wp.abs(qx) + wp.abs(qy))
                            else:
                                q = q + 0.5 * (wp.abs(qx) + wp.abs(qy))
                            q = wp.clamp(q, qmin, qmax)
                        elif wp.static(conservative):
                            covered = l0 + hx0 >= 0.0 and l1 + hx1 >= 0.0 and l2 + hx2 >= 0.0
                            # nearest depth over the texel square, kept within the triangle's range
                            if wp.static(persp):
                                q = q + 0.5 * (wp.abs(qx) + wp.abs(qy))
                            else:
                                q = q - 0.5 * (wp.abs(qx) + wp.abs(qy))
                            q = wp.clamp(q, qmin, qmax)
                        else:
                            covered = l0 >= 0.0 and l1 >= 0.0 and l2 >= 0.0
                    if wp.static(alpha or bary):
                        if covered and (alpha_on != 0 or wp.static(bary)):
                            w = corner_weights(l0, l1, l2, qa, qb, qc, wp.static(int(persp)), wa, wb, wc)
                            if wp.static(alpha):
                                if alpha_on != 0 and w[0] + w[1] + w[2] > 0.0:
                                    covered = surface_present(cut, tri, w[0], w[1], w[2])
                if covered:
                    z = q
                    if wp.static(persp):
                        z = 1.0 / wp.max(q, 1.0e-30)
                    if z <= lv.far:  # behind every receiver: shadows nothing
                        wp.static(frag)(target, x, y, z, w, tri)

    return wp.func(raster_triangle, module="unique")


@wp.struct
class InstanceBatch:
    """The instances of one prototype, for an instanced run (:meth:`Rasterizer.run`): work item
    ``k`` is triangle ``k % ntri`` of the prototype (``points`` / ``indices`` then hold the
    prototypes', :class:`~wsoft.scene.instancing.DeviceInstances`) placed by instance ``k // ntri``."""

    to_world: wp.array[wp.mat44]  # [n] the instances' transforms
    cull_off: wp.array[wp.int32]  # [n] 1: keep every face of this instance (the view's origin is in its bounds)
    mirrored: wp.array[wp.int32]  # [n] 1: its winding flips (closed faces' outward side is the other one)
    ntri: int  # the prototype's triangles
    first: int  # its first triangle in ``indices``
    tri0: int  # its first triangle's combined index (cutouts, cull flags, the fragment's ``tri``)


@wp.kernel
def project_points(
    offset: int,
    points: wp.array[wp.vec3],
    lv: ViewGPU,
    # outputs
    proj: wp.array[wp.vec3],
):
    """Each point's texel coordinates (x, y; zeros for a perspective view's points before its near
    plane, which only clipped triangles have) and view depth (z), as the triangle kernel computes them."""
    i = wp.tid() + offset
    v = view_of(lv, points[i])
    t = wp.vec2(0.0)
    if lv.persp == 0 or v[2] >= lv.near:
        t = texel_of(lv, v)
    proj[i] = wp.vec3(t[0], t[1], v[2])


def _make_kernel(persp: bool, spec: FragmentSpec, conservative: bool, alpha: bool, listed: bool, defer_big: bool, inner: bool = False,
                 instanced: bool = False, preproj: bool = False):
    """One thread per (band of rows, triangle): project, cull, clip at the near plane, scan-convert.
    ``instanced``: work items are (instance, prototype triangle) pairs of an :class:`InstanceBatch`.
    ``preproj``: the points' texel coordinates and depths come from ``proj`` (:func:`project_points`,
    once per point rather than once per corner; a mesh has about half as many points as triangles)."""
    Target = spec.target
    raster_triangle = _make_raster_triangle(persp, spec, conservative, alpha, inner)

    def rasterize_triangles(
        offset: int,
        band_start: int,
        band_rows: int,
        tri_list: wp.array[wp.int32],
        big_texels: float,
        points: wp.array[wp.vec3],
        indices: wp.array[wp.int32],
        lv: ViewGPU,
        cut: Surfaces,
        batch: InstanceBatch,
        proj: wp.array[wp.vec3],
        # outputs
        target: Target,
        big: wp.array[wp.int32],
    ):
        # listed: triangles are tri_list[t + offset]; defer_big: triangles whose texel bounding box
        # exceeds big_texels (or that cross the near plane) are only flagged in big, for a banded pass
        bi, t = wp.tid()
        band = bi + band_start
        item = t + offset
        if wp.static(listed):
            item = tri_list[item]
        row0 = band * band_rows
        row1 = wp.min(row0 + band_rows, lv.height)
        tri = item  # the combined triangle index
        cull = int(0)
        pa = wp.vec3(0.0)
        pb = wp.vec3(0.0)
        pc = wp.vec3(0.0)
        ia = int(0)
        ib = int(0)
        ic = int(0)
        if wp.static(instanced):
            i = item // batch.ntri
            k = item - i * batch.ntri
            tri = batch.tri0 + k
            m = batch.to_world[i]
            g = batch.first + k
            pa = wp.transform_point(m, points[indices[3 * g]])
            pb = wp.transform_point(m, points[indices[3 * g + 1]])
            pc = wp.transform_point(m, points[indices[3 * g + 2]])
            cull = cut.cull[tri]
            if batch.cull_off[i] != 0:
                cull = 0
            elif batch.mirrored[i] != 0:
                cull = -cull  # the transform turns the outward side inward
        else:
            ia = indices[3 * tri]
            ib = indices[3 * tri + 1]
            ic = indices[3 * tri + 2]
            cull = cut.cull[tri]
            if not wp.static(preproj) or cull != 0:  # preproj: the points only for the facing test
                pa = points[ia]
                pb = points[ib]
                pc = points[ic]
        if cull == CULL_SKIP:
            return
        if cull != 0:
            # closed surface: only faces turned toward the light can be nearest (+1 outward, -1 inward)
            n = wp.cross(pb - pa, pc - pa)
            toward = wp.dot(n, lv.az) < 0.0
            if wp.static(persp):
                toward = wp.dot(n, pa - lv.origin) < 0.0
            if toward != (cull > 0):
                return
        a = wp.vec3(0.0)
        b = wp.vec3(0.0)
        c = wp.vec3(0.0)
        if wp.static(preproj):
            a = proj[ia]  # texel x, y and view depth
            b = proj[ib]
            c = proj[ic]
        else:
            a = view_of(lv, pa)
            b = view_of(lv, pb)
            c = view_of(lv, pc)
        zmax = wp.max(a[2], wp.max(b[2], c[2]))
        zmin = wp.min(a[2], wp.min(b[2], c[2]))
        clipped = False
        if wp.static(persp):
            if zmax < lv.near or zmin > lv.far:
                return
            clipped = zmin < lv.near
        ta = wp.vec2(0.0)
        tb = wp.vec2(0.0)
        tc = wp.vec2(0.0)
        if not clipped:
            if wp.static(preproj):
                ta = wp.vec2(a[0], a[1])
                tb = wp.vec2(b[0], b[1])
                tc = wp.vec2(c[0], c[1])
            else:
                ta = texel_of(lv, a)
                tb = texel_of(lv, b)
                tc = texel_of(lv, c)
        if wp.static(defer_big):
            if clipped:
                big[item] = 1
                return
            bw = wp.min(wp.max(ta[0], wp.max(tb[0], tc[0])), float(lv.width)) - wp.max(wp.min(ta[0], wp.min(tb[0], tc[0])), 0.0)
            bh = wp.min(wp.max(ta[1], wp.max(tb[1], tc[1])), float(lv.height)) - wp.max(wp.min(ta[1], wp.min(tb[1], tc[1])), 0.0)
            if bw < 0.0 or bh < 0.0:
                return
            if bw * bh > big_texels:
                big[item] = 1
                return
        alpha_on = int(0)
        if wp.static(alpha):
            if cut.tri_cut[tri] >= 0:
                alpha_on = 1
        ea = wp.vec3(1.0, 0.0, 0.0)
        eb = wp.vec3(0.0, 1.0, 0.0)
        ec = wp.vec3(0.0, 0.0, 1.0)
        if not clipped:
            raster_triangle(lv, tri, ta, tb, tc, a[2], b[2], c[2], ea, eb, ec, row0, row1, cut, alpha_on, target)
            return
        if wp.static(preproj):  # clipping needs the corners' view-space x, y
            a = view_of(lv, points[ia])
            b = view_of(lv, points[ib])
            c = view_of(lv, points[ic])
        # Sutherland-Hodgman against z >= near: 1 or 2 triangles
        n_in = int(0)
        if a[2] >= lv.near:
            n_in += 1
        if b[2] >= lv.near:
            n_in += 1
        if c[2] >= lv.near:
            n_in += 1
        # rotate so that the odd vertex is first
        p0 = a
        p1 = b
        p2 = c
        w0 = ea
        w1 = eb
        w2 = ec
        odd_in = n_in == 1
        if (b[2] >= lv.near) == odd_in:
            p0 = b
            p1 = c
            p2 = a
            w0 = eb
            w1 = ec
            w2 = ea
        elif (c[2] >= lv.near) == odd_in:
            p0 = c
            p1 = a
            p2 = b
            w0 = ec
            w1 = ea
            w2 = eb
        k01 = clip_point(p0, p1, lv.near)
        k02 = clip_point(p0, p2, lv.near)
        q01 = wp.vec3(k01[0], k01[1], k01[2])
        q02 = wp.vec3(k02[0], k02[1], k02[2])
        u01 = w0 + (w1 - w0) * k01[3]
        u02 = w0 + (w2 - w0) * k02[3]
        if odd_in:  # only p0 in front: one triangle p0, q01, q02
            raster_triangle(lv, tri, texel_of(lv, p0), texel_of(lv, q01), texel_of(lv, q02), p0[2], q01[2], q02[2], w0, u01, u02, row0, row1, cut, alpha_on, target)
        else:  # p0 behind: quad q01, p1, p2, q02
            t01 = texel_of(lv, q01)
            t2 = texel_of(lv, p2)
            raster_triangle(lv, tri, t01, texel_of(lv, p1), t2, q01[2], p1[2], p2[2], u01, w1, w2, row0, row1, cut, alpha_on, target)
            raster_triangle(lv, tri, t01, t2, texel_of(lv, q02), q01[2], p2[2], q02[2], u01, w2, u02, row0, row1, cut, alpha_on, target)

    return wp.kernel(rasterize_triangles, module="unique")


@dataclass
class RasterStats:
    """What a run did: private targets merged (CPU), triangles in the banded second pass, bands."""

    private_targets: int = 0
    big_triangles: int = 0
    bands: int = 0


@dataclass
class InstanceRun:
    """The instances of one prototype to draw in a :meth:`Rasterizer.run`: ``count`` instances of the
    :class:`InstanceBatch`, whose triangles index ``points`` / ``indices`` (the prototypes')."""

    batch: object  # InstanceBatch
    count: int
    points: wp.array
    indices: wp.array


@dataclass
class _Segment:
    """What one part of a run draws: its geometry arrays, batch, work items (``ntri``), the length of
    its big-triangle flags (``items``), whether it is listed / instanced, and its triangle list."""

    points: wp.array
    indices: wp.array
    batch: object
    ntri: int
    items: int
    listed: bool
    instanced: bool
    tri_list: wp.array
    proj: wp.array = None  # the points' texel coordinates and depths (:func:`project_points`), or None


@dataclass(eq=False)
class Rasterizer:
    """Kernels of one (projection, fragment, conservative, alpha, inner) combination and their
    scheduling. Made by :func:`make_rasterizer`; kernels are generated on first use."""

    persp: bool
    spec: FragmentSpec
    conservative: bool
    alpha: bool
    inner: bool = False
    _kernels: dict = field(default_factory=dict)

    def kernel(self, listed: bool, defer_big: bool, instanced: bool = False, preproj: bool = False):
        preproj = preproj and not instanced  # an instance's points are placed per instance: never projected first
        key = (listed, defer_big, instanced, preproj)
        if key not in self._kernels:
            self._kernels[key] = _make_kernel(self.persp, self.spec, self.conservative, self.alpha, listed, defer_big, self.inner, instanced, preproj)
        return self._kernels[key]

    def run(self, points: wp.array, indices: wp.array, cut: Surfaces, view, target, device: str, *,
            triangles: wp.array | None = None, initialized: bool = True, strategy: str = "auto",
            batches: "list[InstanceRun] | None" = None, preproject: bool | None = None) -> RasterStats:
        """Rasterize the triangles (all of ``indices``, or the index list ``triangles``) into ``target``.

        ``initialized = False``: ``target`` holds no data yet; the CPU's first worker clears it as
        its private target (saves a clear and a merge). ``strategy``: ``auto`` (private targets
        when the fragment can merge, else bands), ``private`` or ``bands``. ``batches``: instances
        drawn in the same run (:class:`InstanceRun`: one per prototype, its work items (instance,
        prototype triangle)), sharing the CPU's private targets and their one merge with the
        triangles of ``indices``. ``preproject``: project every point once first (:func:`project_points`)
        rather than each triangle's corners; default: yes, unless a triangle list is shorter than a third
        of the point count. The map is the same bit for bit either way."""
        lv = view.gpu() if isinstance(view, LightView) else view
        if bool(lv.persp) != self.persp:
            raise ValueError("the view's projection does not match the rasterizer's")
        w, h = lv.width, lv.height
        listed = triangles is not None
        no_list = triangles if listed else wp.zeros(1, dtype=wp.int32, device=device)
        no_big = wp.zeros(1, dtype=wp.int32, device=device)
        no_proj = wp.zeros(1, dtype=wp.vec3, device=device)
        # segments: the soup's triangles, then each prototype's instances
        segs = [_Segment(points, indices, _no_batch(device), indices.shape[0] // 3 if triangles is None else triangles.shape[0],
                         indices.shape[0] // 3, listed, False, no_list)]
        for br in batches or ():
            n = int(br.count) * int(br.batch.ntri)
            segs.append(_Segment(br.points, br.indices, br.batch, n, n, False, True, no_list))
        segs = [g for g in segs if g.ntri > 0]
        if preproject is None:
            preproject = bool(segs) and not segs[0].instanced and 3 * segs[0].ntri >= points.shape[0]
        if preproject and segs and not segs[0].instanced:
            # project each point once rather than each triangle's corners: worth it unless a short
            # triangle list uses few of the points
            segs[0].proj = wp.empty(points.shape[0], dtype=wp.vec3, device=device)
            launch_chunked(project_points, points.shape[0], inputs=[points, lv], outputs=[segs[0].proj], device=device, min_chunk=1 << 15)
        ntri = sum(g.ntri for g in segs)
        stats = RasterStats()
        if strategy == "auto":
            strategy = "private" if self.spec.merge is not None else "bands"
        if strategy == "private" and self.spec.merge is None:
            raise ValueError(f"fragment {self.spec.name} cannot merge private targets")

        def launcher(g: "_Segment"):
            def launch(kernel, tgt, start, count, nbands, band_rows, band_start=0, tri_list=g.tri_list, big_texels=0.0, big=no_big):
                wp.launch(kernel, dim=(nbands, count), inputs=[start, band_start, band_rows, tri_list, float(big_texels), g.points, g.indices, lv, cut,
                                                               g.batch, no_proj if g.proj is None else g.proj], outputs=[tgt, big], device=device)

            return launch

        if ntri == 0:
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            return stats
        if not device.startswith("cpu"):
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            nb = (h + GPU_BAND_ROWS - 1) // GPU_BAND_ROWS
            for g in segs:
                launcher(g)(self.kernel(g.listed, False, g.instanced, g.proj is not None), target, 0, g.ntri, nb, GPU_BAND_ROWS)
            stats.bands = nb
            return stats
        if strategy == "bands":
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            for g in segs:
                self._bands(launcher(g), self.kernel(g.listed, False, g.instanced, g.proj is not None), target, g.ntri, h, g.tri_list, stats, device)
            return stats
        # CPU phase 1: each worker rasterizes interleaved chunks of small triangles into its own target
        kernels1 = [self.kernel(g.listed, True, g.instanced, g.proj is not None) for g in segs]
        for k in kernels1:
            ensure_loaded(k, device)
        target_bytes = 4 * w * h
        nchunks = sum((g.ntri + CPU_CHUNK - 1) // CPU_CHUNK for g in segs)
        nmaps = max(1, min(cpu_threads(), PRIVATE_BUDGET // max(target_bytes, 1), nchunks))
        own = 0 if initialized else 1  # workers that adopt the (uninitialised) target itself
        privates = [target] * own + [self.spec.private(target, device) for _ in range(nmaps - own)]
        chunks = [(j, s0, min(CPU_CHUNK, g.ntri - s0)) for j, g in enumerate(segs) for s0 in range(0, g.ntri, CPU_CHUNK)]
        bigs = [wp.zeros(g.items, dtype=wp.int32, device=device) for g in segs]  # flags by triangle index (by work item for instances)
        launches = [launcher(g) for g in segs]

        def worker(m):
            def run():
                self.spec.clear(privates[m], device)
                for j, start, count in chunks[m::nmaps]:
                    launches[j](kernels1[j], privates[m], start, count, 1, h, big_texels=BIG_TRIANGLE_TEXELS, big=bigs[j])

            return run

        run_tasks([worker(m) for m in range(nmaps)], device)
        self.spec.merge(privates[own:], target, device)
        stats.private_targets = nmaps
        # CPU phase 2: large (and near-clipped) triangles, shared out by disjoint bands of rows
        for j, g in enumerate(segs):
            big_list = np.flatnonzero(bigs[j].numpy()).astype(np.int32)
            stats.big_triangles += int(len(big_list))
            if len(big_list):
                blist = wp.array(big_list, dtype=wp.int32, device=device)
                self._bands(launches[j], self.kernel(True, False, g.instanced, g.proj is not None), target, len(big_list), h, blist, stats, device)
        return stats

    @staticmethod
    def _bands(launch, kernel, target, ntri, h, tri_list, stats, device):
        """Every worker a disjoint band of rows, every triangle (its rows clipped to the band)."""
        ensure_loaded(kernel, device)
        nb = max(1, min(h, cpu_threads() * 4))
        rows = (h + nb - 1) // nb
        nb = (h + rows - 1) // rows
        stats.bands = nb

        def band_task(b):
            return lambda: launch(kernel, target, 0, ntri, 1, rows, band_start=b, tri_list=tri_list)

        run_tasks([band_task(b) for b in range(nb)], device)


_RASTERIZERS: dict[tuple, Rasterizer] = {}
_NO_BATCH: dict[str, InstanceBatch] = {}


def _no_batch(device: str) -> InstanceBatch:
    """The batch a run without instances passes (never read)."""
    if device not in _NO_BATCH:
        b = InstanceBatch()
        b.to_world = wp.array(np.eye(4, dtype=np.float32)[None], dtype=wp.mat44, device=device)
        b.cull_off = wp.zeros(1, dtype=wp.int32, device=device)
        b.mirrored = wp.zeros(1, dtype=wp.int32, device=device)
        b.ntri, b.first, b.tri0 = 1, 0, 0
        _NO_BATCH[device] = b
    return _NO_BATCH[device]


def make_rasterizer(view, fragment_func, *, conservative: bool = False, alpha: bool = False, inner: bool = False) -> Rasterizer:
    """The rasterizer of ``view``'s projection (``"perspective"``, ``"orthographic"``, a
    :class:`LightView` or a :class:`ViewGPU`) that calls ``fragment_func`` (a fragment made with
    :func:`fragment`) per covered texel, conservative or not (``inner``: only texels covered whole,
    at their farthest depth; needs ``conservative``), alpha-tested or not. Cached."""
    if inner and not conservative:
        raise ValueError("inner coverage is a conservative mode: pass conservative=True")
    if isinstance(view, str):
        if view not in (PERSPECTIVE, ORTHOGRAPHIC):
            raise ValueError(f"view {view!r} is not {PERSPECTIVE} or {ORTHOGRAPHIC}")
        persp = view == PERSPECTIVE
    else:
        persp = bool(view.persp)
    spec = FRAGMENTS.get(getattr(fragment_func, "key", None))
    if spec is None or spec.func is not fragment_func:
        raise ValueError(f"{fragment_func!r} is not a registered fragment (make it with @fragment)")
    key = (persp, spec.name, bool(conservative), bool(alpha), bool(inner))
    if key not in _RASTERIZERS:
        _RASTERIZERS[key] = Rasterizer(persp, spec, bool(conservative), bool(alpha), bool(inner))
    return _RASTERIZERS[key]


# --------------------------------------------------------------------------- depth maps


@dataclass
class DepthMap:
    """Light-space linear depth, shape ``[height, width]`` float32; ``DEPTH_CLEAR`` where empty."""

    view: LightView
    depth: wp.array
    alpha_tested: bool
    conservative: bool
    inner: bool = False  # texels certainly blocked (inner coverage, farthest depth), else DEPTH_CLEAR
    private_maps: int = 0  # CPU worker maps merged into ``depth`` (temporaries, freed)
    big_triangles: int = 0  # CPU: triangles rasterized in the banded second pass
    instances_drawn: int = 0  # instanced scene: instances whose bounds reach the view (drawn)

    def arrays(self) -> dict[str, wp.array]:
        return {"depth": self.depth}


def rasterize(
    ds: DeviceScene,
    view: LightView,
    alpha_tested: bool,
    conservative: bool = False,
    triangles: np.ndarray | None = None,
    behind: wp.array | None = None,
    inner: bool = False,
    faces: str = "all",
) -> DepthMap:
    """Rasterize the scene (or only ``triangles``, an index array) into a depth map for ``view``.

    ``behind``: a depth map of the same size; only surfaces behind it are written (the
    inverted depth test, :func:`gated_depth_min`; texels where it is empty receive nothing).
    ``inner``: per texel the nearest of the farthest depths of the triangles that cover it whole
    (cutouts never do), far faces included (each adds coverage): a depth every ray through the
    texel is certainly blocked at; ``DEPTH_CLEAR`` where no triangle covers the texel whole.
    ``faces``: ``all``, or only ``back`` / ``open`` faces (:func:`~wsoft.scene.device.face_surfaces`)."""
    dev = ds.device
    shape = (view.height, view.width)
    alpha = bool((alpha_tested or inner) and ds.has_cutouts)
    subset = None if triangles is None else wp.array(np.asarray(triangles, np.int32), dtype=wp.int32, device=dev)
    if behind is None:
        target = DepthTarget()
        frag = depth_min
    else:
        target = GatedDepthTarget()
        target.gate = behind
        frag = gated_depth_min
    target.depth = wp.empty(shape, dtype=float, device=dev)
    r = make_rasterizer(view, frag, conservative=conservative or inner, alpha=alpha, inner=inner)
    if faces != "all":
        surfaces = face_surfaces(ds, view.origin if view.persp else None, faces)
    elif inner:
        surfaces = without_culling(ds.cutouts, ds.tri_total, dev)
    else:
        surfaces = view_surfaces(ds, view.origin if view.persp else None)  # no far-face skipping around a light inside a closed mesh
    runs, placed = [], 0
    if ds.instances is not None:
        if inner or faces != "all" or triangles is not None:
            raise ValueError("an instanced scene's maps draw every face of every caster (no inner coverage, face subsets or triangle lists)")
        runs, placed = instance_runs(ds, view)
    st = r.run(ds.points, ds.indices, surfaces, view, target, dev, triangles=subset, initialized=False, batches=runs)
    return DepthMap(view=view, depth=target.depth, alpha_tested=alpha, conservative=conservative or inner, inner=inner,
                    private_maps=st.private_targets, big_triangles=st.big_triangles, instances_drawn=placed)


def instance_runs(ds: DeviceScene, view: LightView) -> tuple[list[InstanceRun], int]:
    """An instanced scene's instances to draw into ``view`` (for :meth:`Rasterizer.run`): per
    prototype one :class:`InstanceRun` of the instances whose world bounds can reach the view
    (:func:`~wsoft.lightspace.view.boxes_in_view`), split where its work items would pass 2^30
    (they are int32). Returns (runs, instances drawn)."""
    di = ds.instances
    dev = ds.device
    seen, origin_inside = boxes_in_view(view, di.lo, di.hi)
    runs, drawn = [], 0
    for p in range(len(di.proto_ntri)):
        sel = np.flatnonzero(seen & (di.proto == p))
        if len(sel) == 0 or di.proto_ntri[p] == 0:
            continue
        per_run = max(1, (1 << 30) // int(di.proto_ntri[p]))
        for a in range(0, len(sel), per_run):
            part = sel[a: a + per_run]
            b = InstanceBatch()
            b.to_world = wp.array(di.to_world[part].astype(np.float32), dtype=wp.mat44, device=dev)
            b.cull_off = wp.array(origin_inside[part].astype(np.int32), dtype=wp.int32, device=dev)
            b.mirrored = wp.array(di.mirrored[part].astype(np.int32), dtype=wp.int32, device=dev)
            b.ntri = int(di.proto_ntri[p])
            b.first = int(di.proto_first[p])
            b.tri0 = int(di.tri_base + di.proto_first[p])
            runs.append(InstanceRun(b, len(part), di.proto_points, di.proto_indices))
        drawn += len(sel)
    return runs, drawn
