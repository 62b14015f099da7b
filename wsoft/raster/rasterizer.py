"""The software rasterizer of light views (and any view): scan-converts triangles into a map.

:func:`rasterize` fills a ``[H, W]`` map of light-space *linear* depth (distance along the view
axis) by scan-converting every triangle in Warp: near-plane clipping, perspective-correct depth
and uv, alpha test for cutouts, and an optional conservative mode that writes every texel a
triangle touches.

Each triangle is visited once. On CPU every worker thread rasterizes its share of the
triangles into a private map (interleaved chunks, so clustered geometry is shared out) and
the maps are merged by a parallel ``min``; on CUDA one launch splits the map into bands of
rows (so a large triangle is shared by many threads) and writes with ``atomic_min``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU, texel_of, view_of
from wsoft.parallel import cpu_threads, ensure_loaded, launch_chunked, run_tasks
from wsoft.scene.device import DeviceScene, Surfaces, surface_present

GPU_BAND_ROWS = 64  # CUDA: rows per band (one thread per triangle and band)
SMALL_BOX_TEXELS = wp.constant(8)  # triangles whose texel box is this small take the flat loop
CPU_CHUNK = 32768  # CPU: triangles per launch; a worker's chunks are interleaved with the others'
BIG_TRIANGLE_TEXELS = 4096  # CPU: triangles with a larger texel bounding box go to the banded pass
PRIVATE_MAP_BUDGET = 1 << 30  # CPU: bytes allowed for per-worker private depth maps


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
    alpha: int,
    conservative: int,
    gate: wp.array2d[float],
    use_gate: int,
    depth: wp.array2d[float],
):
    """Scan-convert one (clipped) triangle into rows [row0, row1).

    With ``use_gate``, a texel is written only where the surface lies behind ``gate`` (the
    inverted depth test of Salzman's far bound: surfaces behind the casters).

    ``ta, tb, tc``: corners in texel coordinates; ``za, zb, zc``: their view depths;
    ``wa, wb, wc``: the corners' weights of the original triangle (for the uv of the alpha test).
    """
    area = edge(ta[0], ta[1], tb[0], tb[1], tc[0], tc[1])
    if wp.abs(area) < 1.0e-12:
        return
    xmin = wp.min(ta[0], wp.min(tb[0], tc[0]))
    xmax = wp.max(ta[0], wp.max(tb[0], tc[0]))
    ymin = wp.min(ta[1], wp.min(tb[1], tc[1]))
    ymax = wp.max(ta[1], wp.max(tb[1], tc[1]))
    x0 = int(0)
    x1 = int(0)
    y0 = int(0)
    y1 = int(0)
    if conservative != 0:
        x0 = int(wp.floor(xmin))
        x1 = int(wp.floor(xmax))
        y0 = int(wp.floor(ymin))
        y1 = int(wp.floor(ymax))
    else:
        x0 = int(wp.ceil(xmin - 0.5))
        x1 = int(wp.floor(xmax - 0.5))
        y0 = int(wp.ceil(ymin - 0.5))
        y1 = int(wp.floor(ymax - 0.5))
    x0 = wp.max(x0, 0)
    x1 = wp.min(x1, lv.width - 1)
    y0 = wp.max(y0, row0)
    y1 = wp.min(y1, row1 - 1)
    if x0 > x1 or y0 > y1:  # covers no texel centre (most small triangles of a dense mesh)
        return
    inv_area = 1.0 / area
    # interpolated quantity: q = 1/z (perspective) or z (orthographic); both affine in texel space
    qa = za
    qb = zb
    qc = zc
    if lv.persp != 0:
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
    if conservative != 0:
        qmin = wp.min(qa, wp.min(qb, qc))
        qmax = wp.max(qa, wp.max(qb, qc))
        hx0 = 0.5 * (wp.abs(g0x) + wp.abs(g0y))
        hx1 = 0.5 * (wp.abs(g1x) + wp.abs(g1y))
        hx2 = 0.5 * (wp.abs(g2x) + wp.abs(g2y))
    nx = x1 - x0 + 1
    if conservative == 0 and alpha == 0 and nx * (y1 - y0 + 1) <= SMALL_BOX_TEXELS:
        # a small triangle: test every texel centre of its box in one flat loop (fewer branches
        # than lines and spans); barycentrics and q from the box's first centre (no drift this small)
        pxb = float(x0) + 0.5
        pyb = float(y0) + 0.5
        b0 = edge(tb[0], tb[1], tc[0], tc[1], pxb, pyb) * inv_area
        b1 = edge(tc[0], tc[1], ta[0], ta[1], pxb, pyb) * inv_area
        qb0 = b0 * qa + b1 * qb + (1.0 - b0 - b1) * qc
        dx = int(0)
        dy = int(0)
        for _k in range(nx * (y1 - y0 + 1)):
            fx = float(dx)
            fy = float(dy)
            l0 = b0 + g0x * fx + g0y * fy
            l1 = b1 + g1x * fx + g1y * fy
            if l0 >= 0.0 and l1 >= 0.0 and 1.0 - l0 - l1 >= 0.0:
                z = qb0 + qx * fx + qy * fy
                if lv.persp != 0:
                    z = 1.0 / wp.max(z, 1.0e-30)
                if use_gate == 0:
                    wp.atomic_min(depth, y0 + dy, x0 + dx, z)
                elif z > gate[y0 + dy, x0 + dx] * 1.0001:
                    wp.atomic_min(depth, y0 + dy, x0 + dx, z)
            dx += 1
            if dx == nx:
                dx = 0
                dy += 1
        return
    # plain case (no alpha test, not conservative): walk the exact span of covered texel
    # centres on each line and evaluate the depth plane directly at each texel. Lines run along
    # the bounding box's longer side (columns for a tall, thin triangle): fewer, longer spans.
    spans = conservative == 0 and alpha == 0
    cols = spans and (y1 - y0) > (x1 - x0)
    o0 = y0
    o1 = y1
    n0 = x0
    n1 = x1
    h0 = g0x
    h1 = g1x
    h2 = g2x
    qn = qx
    if cols:
        o0 = x0
        o1 = x1
        n0 = y0
        n1 = y1
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
        ns = n0
        ne = n1
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
            ns = wp.max(n0, int(wp.ceil(lim[0] - 0.5)))
            ne = wp.min(n1, int(wp.floor(lim[1] - 0.5)))
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
            if not spans:
                # evaluated per texel, not stepped: stepping drifts on wide triangles
                l0 = edge(tb[0], tb[1], tc[0], tc[1], px, py) * inv_area
                l1 = edge(tc[0], tc[1], ta[0], ta[1], px, py) * inv_area
                l2 = 1.0 - l0 - l1
                if conservative != 0:
                    covered = l0 + hx0 >= 0.0 and l1 + hx1 >= 0.0 and l2 + hx2 >= 0.0
                    # nearest depth over the texel square, kept within the triangle's range
                    if lv.persp != 0:
                        q = q + 0.5 * (wp.abs(qx) + wp.abs(qy))
                    else:
                        q = q - 0.5 * (wp.abs(qx) + wp.abs(qy))
                    q = wp.clamp(q, qmin, qmax)
                else:
                    covered = l0 >= 0.0 and l1 >= 0.0 and l2 >= 0.0
                if covered and alpha != 0:
                    c0 = wp.max(l0, 0.0)
                    c1 = wp.max(l1, 0.0)
                    c2 = wp.max(l2, 0.0)
                    if lv.persp != 0:  # perspective-correct weights
                        c0 = c0 * qa
                        c1 = c1 * qb
                        c2 = c2 * qc
                    s = c0 + c1 + c2
                    if s > 0.0:
                        w = (wa * c0 + wb * c1 + wc * c2) / s
                        covered = surface_present(cut, tri, w[0], w[1], w[2])
            if covered:
                z = q
                if lv.persp != 0:
                    z = 1.0 / wp.max(q, 1.0e-30)
                if use_gate == 0:
                    wp.atomic_min(depth, y, x, z)
                elif z > gate[y, x] * 1.0001:
                    wp.atomic_min(depth, y, x, z)


@wp.func
def clip_point(p: wp.vec3, q: wp.vec3, near: float) -> wp.vec4:
    """Where segment p->q crosses the near plane: the point (xyz) and its parameter along p->q (w)."""
    s = (near - p[2]) / (q[2] - p[2])
    r = p + (q - p) * s
    return wp.vec4(r[0], r[1], r[2], s)


@wp.kernel
def rasterize_depth(
    offset: int,
    band_start: int,
    band_rows: int,
    tri_list: wp.array[wp.int32],
    use_list: int,
    big_texels: float,
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    lv: ViewGPU,
    cut: Surfaces,
    alpha: int,
    conservative: int,
    gate: wp.array2d[float],
    use_gate: int,
    # outputs
    depth: wp.array2d[float],
    big: wp.array[wp.int32],
):
    """One thread per (band of rows, triangle): project, cull, clip at the near plane, scan-convert.

    ``use_list``: triangles are ``tri_list[t + offset]`` instead of ``t + offset``.
    ``big_texels > 0``: triangles whose texel bounding box is larger (or that cross the near
    plane) are only flagged in ``big`` and left for a banded pass.
    """
    bi, t = wp.tid()
    band = bi + band_start
    tri = t + offset
    if use_list != 0:
        tri = tri_list[tri]
    row0 = band * band_rows
    row1 = wp.min(row0 + band_rows, lv.height)
    pa = points[indices[3 * tri]]
    pb = points[indices[3 * tri + 1]]
    pc = points[indices[3 * tri + 2]]
    cull = cut.cull[tri]
    if cull != 0:
        # closed surface: only faces turned toward the light can be nearest (+1 outward, -1 inward)
        n = wp.cross(pb - pa, pc - pa)
        toward = wp.dot(n, lv.az) < 0.0
        if lv.persp != 0:
            toward = wp.dot(n, pa - lv.origin) < 0.0
        if toward != (cull > 0):
            return
    a = view_of(lv, pa)
    b = view_of(lv, pb)
    c = view_of(lv, pc)
    zmax = wp.max(a[2], wp.max(b[2], c[2]))
    zmin = wp.min(a[2], wp.min(b[2], c[2]))
    if lv.persp != 0 and (zmax < lv.near or zmin > lv.far):
        return
    clipped = lv.persp != 0 and zmin < lv.near
    ta = wp.vec2(0.0)
    tb = wp.vec2(0.0)
    tc = wp.vec2(0.0)
    if not clipped:
        ta = texel_of(lv, a)
        tb = texel_of(lv, b)
        tc = texel_of(lv, c)
    if big_texels > 0.0:
        if clipped:
            big[tri] = 1
            return
        bw = wp.min(wp.max(ta[0], wp.max(tb[0], tc[0])), float(lv.width)) - wp.max(wp.min(ta[0], wp.min(tb[0], tc[0])), 0.0)
        bh = wp.min(wp.max(ta[1], wp.max(tb[1], tc[1])), float(lv.height)) - wp.max(wp.min(ta[1], wp.min(tb[1], tc[1])), 0.0)
        if bw < 0.0 or bh < 0.0:
            return
        if bw * bh > big_texels:
            big[tri] = 1
            return
    alpha_on = int(0)
    if alpha != 0:
        if cut.tri_cut[tri] >= 0:
            alpha_on = 1
    ea = wp.vec3(1.0, 0.0, 0.0)
    eb = wp.vec3(0.0, 1.0, 0.0)
    ec = wp.vec3(0.0, 0.0, 1.0)
    if not clipped:
        raster_triangle(lv, tri, ta, tb, tc, a[2], b[2], c[2], ea, eb, ec, row0, row1, cut, alpha_on, conservative, gate, use_gate, depth)
        return
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
        raster_triangle(lv, tri, texel_of(lv, p0), texel_of(lv, q01), texel_of(lv, q02), p0[2], q01[2], q02[2], w0, u01, u02, row0, row1, cut, alpha_on, conservative, gate, use_gate, depth)
    else:  # p0 behind: quad q01, p1, p2, q02
        t01 = texel_of(lv, q01)
        t2 = texel_of(lv, p2)
        raster_triangle(lv, tri, t01, texel_of(lv, p1), t2, q01[2], p1[2], p2[2], u01, w1, w2, row0, row1, cut, alpha_on, conservative, gate, use_gate, depth)
        raster_triangle(lv, tri, t01, t2, texel_of(lv, q02), q01[2], p2[2], q02[2], u01, w2, u02, row0, row1, cut, alpha_on, conservative, gate, use_gate, depth)


@wp.kernel
def fill_depth(value: float, dst: wp.array[float]):
    dst[wp.tid()] = value


@wp.kernel
def merge_min(offset: int, src: wp.array[float], dst: wp.array[float]):
    """dst = min(dst, src), element-wise over flat maps."""
    i = wp.tid() + offset
    dst[i] = wp.min(dst[i], src[i])


@dataclass
class DepthMap:
    """Light-space linear depth, shape ``[height, width]`` float32; ``DEPTH_CLEAR`` where empty."""

    view: LightView
    depth: wp.array
    alpha_tested: bool
    conservative: bool
    private_maps: int = 0  # CPU worker maps merged into ``depth`` (temporaries, freed)
    big_triangles: int = 0  # CPU: triangles rasterized in the banded second pass

    def arrays(self) -> dict[str, wp.array]:
        return {"depth": self.depth}


def rasterize(
    ds: DeviceScene,
    view: LightView,
    alpha_tested: bool,
    conservative: bool = False,
    triangles: np.ndarray | None = None,
    behind: wp.array | None = None,
) -> DepthMap:
    """Rasterize the scene (or only ``triangles``, an index array) into a depth map for ``view``.

    ``behind``: a depth map of the same size; only surfaces behind it are written (the
    inverted depth test; texels where it is empty receive nothing).
    """
    dev = ds.device
    lv = view.gpu()
    shape = (view.height, view.width)
    alpha = int(alpha_tested and ds.has_cutouts)
    cons = int(conservative)
    ensure_loaded(rasterize_depth, dev)  # the module also holds fill_depth and merge_min
    no_list = wp.zeros(1, dtype=wp.int32, device=dev)
    no_gate = wp.zeros((1, 1), dtype=float, device=dev)
    gate = behind if behind is not None else no_gate
    subset = None
    if triangles is not None:
        subset = wp.array(np.asarray(triangles, np.int32), dtype=wp.int32, device=dev)
    ntri = ds.indices.shape[0] // 3 if subset is None else subset.shape[0]

    def launch(target, start, count, nbands, band_rows, band_start=0, tri_list=None, big_texels=0.0, big=None):
        if tri_list is None:
            tri_list = subset
        wp.launch(
            rasterize_depth, dim=(nbands, count),
            inputs=[start, band_start, band_rows, tri_list if tri_list is not None else no_list, int(tri_list is not None), float(big_texels),
                    ds.points, ds.indices, lv, ds.cutouts, alpha, cons, gate, int(behind is not None)],
            outputs=[target, big if big is not None else no_list], device=dev,
        )

    if ntri == 0:
        return DepthMap(view=view, depth=wp.full(shape, DEPTH_CLEAR, dtype=float, device=dev), alpha_tested=bool(alpha), conservative=conservative)
    if not dev.startswith("cpu"):
        depth = wp.full(shape, DEPTH_CLEAR, dtype=float, device=dev)
        nb = (view.height + GPU_BAND_ROWS - 1) // GPU_BAND_ROWS
        launch(depth, 0, ntri, nb, GPU_BAND_ROWS)
        return DepthMap(view=view, depth=depth, alpha_tested=bool(alpha), conservative=conservative, private_maps=0)
    # CPU phase 1: each worker rasterizes interleaved chunks of small triangles into its own map
    map_bytes = 4 * view.width * view.height
    nmaps = max(1, min(cpu_threads(), PRIVATE_MAP_BUDGET // map_bytes, (ntri + CPU_CHUNK - 1) // CPU_CHUNK))
    maps = [wp.empty(shape, dtype=float, device=dev) for _ in range(nmaps)]  # each worker clears its own
    chunks = [(s, min(CPU_CHUNK, ntri - s)) for s in range(0, ntri, CPU_CHUNK)]
    big = wp.zeros(ds.indices.shape[0] // 3, dtype=wp.int32, device=dev)  # flags by triangle index
    big_texels = float(max(BIG_TRIANGLE_TEXELS, 1))

    def worker(m):
        def run():
            wp.launch(fill_depth, dim=view.width * view.height, inputs=[DEPTH_CLEAR], outputs=[maps[m].reshape(-1)], device=dev)
            for start, count in chunks[m::nmaps]:
                launch(maps[m], start, count, 1, view.height, big_texels=big_texels, big=big)

        return run

    run_tasks([worker(m) for m in range(nmaps)], dev)
    depth = maps[0]
    flat = depth.reshape(-1)
    for other in maps[1:]:
        launch_chunked(merge_min, flat.shape[0], inputs=[other.reshape(-1)], outputs=[flat], device=dev, min_chunk=1 << 16)
    # CPU phase 2: large (and near-clipped) triangles, shared out by bands of rows of the one map
    big_list = np.flatnonzero(big.numpy()).astype(np.int32)
    if len(big_list):
        blist = wp.array(big_list, dtype=wp.int32, device=dev)
        nb = max(1, min(view.height, cpu_threads() * 4))
        rows = (view.height + nb - 1) // nb
        nb = (view.height + rows - 1) // rows

        def band_task(b):
            return lambda: launch(depth, 0, len(big_list), 1, rows, band_start=b, tri_list=blist)

        run_tasks([band_task(b) for b in range(nb)], dev)
    return DepthMap(view=view, depth=depth, alpha_tested=bool(alpha), conservative=conservative, private_maps=nmaps, big_triangles=int(len(big_list)))
