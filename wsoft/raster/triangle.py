"""The scan conversion of one triangle into a view, specialised at code generation for the
rasterizer (:mod:`wsoft.raster.rasterizer`): coverage of texel centres (or, **conservative**, of
any part of a texel; **inner**, of a whole texel), exact spans of covered texel centres for wide
triangles and one flat loop over a small triangle's box, alpha tests of cutout triangles, the
interpolated depth and corner weights handed to the fragment."""

import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, ViewGPU
from wsoft.scene.surfaces import Surfaces, surface_present

SMALL_BOX_TEXELS = 16  # triangles whose texel box is this small take the flat loop (orthographic views)
SMALL_BOX_TEXELS_PERSP = 8  # the same for perspective views, whose loop divides per covered texel
CONSERVATIVE_MARGIN = wp.constant(1.0e-3)  # texels: conservative coverage reaches this far past a texel, against rounding


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


# --------------------------------------------------------------------------- one triangle


def make_raster_triangle(persp: bool, spec, conservative: bool, alpha: bool, inner: bool = False):
    """The scan conversion of one (clipped) triangle, specialised; calls the fragment of ``spec`` (a
    :class:`~wsoft.raster.rasterizer.FragmentSpec`) per texel."""
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
