"""How much of a light a projected silhouette edge covers: the analytic area integral of the penumbra
wedge algorithm (Akenine-Möller and Assarsson 2002, Assarsson and Akenine-Möller 2003).

Seen from a receiver ``o``, the occluders project onto the light's plane (a rect or disk light's
own plane; a sphere light's silhouette disk facing ``o``; a cylinder light's silhouette rectangle
facing ``o``, :func:`~wsoft.lightspace.light.silhouette_rect`, a line light as a rectangle
:data:`~wsoft.lightspace.light.LINE_WIDTH` of its length wide; a distant light's cone as the disk it
cuts at unit distance along its direction, :func:`light_frame`). Take the light's centre
``c`` and any light point ``x``: the segment ``c x`` lies in the (convex) light, and the occluders'
covering count at ``x`` differs from the one at ``c`` by the signed crossings of ``c x`` with the
projected silhouette edges. Integrating over the light, an edge ``e`` whose projection ``a' b'``
meets the light changes the covered fraction by the area of

    R(e) = { x in light : the segment c x crosses a' b' }

(the part of the light beyond the line ``a' b'`` as seen from ``c``, inside the angle that
``a' b'`` subtends at ``c``), divided by the light's area: added where ``c`` is visible past the
edge (the receiver is outside the edge's hard shadow quad: the edge covers ``R``), subtracted
where ``c`` is hidden (inside: ``R`` is uncovered). Edges whose projection misses the light have
``R`` empty, which is why only the receivers inside an edge's *wedge* need it.

:func:`edge_coverage` computes ``|R| / |light|`` exactly for a rect (the rectangle clipped by the
three half-planes that bound ``R``, Sutherland-Hodgman, shoelace area) and for a disk (the disk's
bounding square clipped the same way, then the exact area of disk ∩ polygon as a sum of
disk ∩ triangle(centre, edge) terms: triangle and circular-sector pieces; an ellipse, an
elliptical disk light's or an ellipsoidal sphere light's silhouette, in coordinates scaled along
its principal axes to the unit disk, an affine map that keeps the ratio). The edge is first
clipped to the slab between the receiver and the light's plane (``s``, the fraction of the way
there, in ``[0, 1]``; a distant light has no far side): parts behind the receiver or beyond the
light block nothing. Projected points are kept homogeneous: a point level with the receiver
(``s = 0``) projects to infinity, and dividing by a small ``s`` (itself the difference of
nearly equal terms near the receiver's level) would turn its rounding into a wrongly turned
edge. A distant light's cone is the disk of radius ``tan(theta)`` it cuts on the
plane at unit distance along its direction (no far-away plane: its coordinates would lose float32
precision), measured by area, not solid angle: the two differ by ``O(theta^2)`` for half-angle
``theta`` (0.02% at the sun's 0.27 degrees, 0.8% at 5 degrees).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.light import LINE_WIDTH, LightGPU, is_round, light_gpu, silhouette_disk, silhouette_ellipse, silhouette_rect

poly_t = wp.types.matrix(shape=(8, 2), dtype=wp.float32)  # a convex polygon: a rectangle clipped by at most 3 lines
INFINITE = wp.constant(1.0e30)


@wp.func
def cross2(a: wp.vec2, b: wp.vec2) -> float:
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def light_frame(L: LightGPU, p: wp.vec3):
    """The light as seen from ``p``: (its centre, unit axes ``u``, ``v`` of its plane, half extents
    (a rect's half width and height, a cylinder's silhouette rectangle's; a disk's two semi-axes, equal when round), 1 for a disk / 0 for a rect, and how
    far past its plane (as a multiple of the way there) a caster can be: 1, or :data:`INFINITE`
    for a distant light, whose plane is put at unit distance from ``p``)."""
    if L.kind == 0:
        return L.position, L.ax, L.ay, L.half_size, int(0), 1.0
    if L.kind == 1:  # an elliptical disk: its two semi-axes
        return L.position, L.ax, L.ay, wp.vec2(L.radius * L.aspect[0], L.radius * L.aspect[1]), int(1), 1.0
    if L.kind == 3:
        t = wp.sqrt(wp.max(1.0 - L.cos_max * L.cos_max, 0.0)) / wp.max(L.cos_max, 1.0e-6)
        return p + L.az, L.ax, L.ay, wp.vec2(t, t), int(1), INFINITE
    if L.kind == 5:  # cylinder: its silhouette rectangle seen from p (as light_point); a line light: LINE_WIDTH wide
        ce, u, v, e = silhouette_rect(L, p)
        return ce, u, v, wp.vec2(e[0], wp.max(e[1], LINE_WIDTH * e[0])), int(0), 1.0
    # sphere: its silhouette disk (an ellipsoid's ellipse) seen from p (as light_point); a point light: a disk of radius 0
    if L.kind == 2 and not is_round(L):
        ce, u, v, e = silhouette_ellipse(L, p)
        return ce, u, v, e, int(1), 1.0
    c, tx, ty, rad = silhouette_disk(L, p)
    if L.kind != 2:
        c = L.position
        rad = 0.0
    return c, tx, ty, wp.vec2(rad, rad), int(1), 1.0


@wp.func
def clip_half(P: poly_t, n: int, h: wp.vec3):
    """The convex polygon ``P[:n]`` clipped to ``h.x x + h.y y + h.z >= 0``: (polygon, count)."""
    Q = poly_t()
    m = int(0)
    for k in range(n):
        kb = k + 1
        if kb == n:
            kb = 0
        ax = P[k, 0]
        ay = P[k, 1]
        bx = P[kb, 0]
        by = P[kb, 1]
        fa = h[0] * ax + h[1] * ay + h[2]
        fb = h[0] * bx + h[1] * by + h[2]
        if fa >= 0.0 and m < 8:
            Q[m, 0] = ax
            Q[m, 1] = ay
            m += 1
        if (fa >= 0.0) != (fb >= 0.0) and m < 8:
            t = fa / (fa - fb)
            Q[m, 0] = ax + t * (bx - ax)
            Q[m, 1] = ay + t * (by - ay)
            m += 1
    return Q, m


@wp.func
def polygon_area(P: poly_t, n: int) -> float:
    """Signed (counter-clockwise positive) area of ``P[:n]``."""
    s = float(0.0)
    for k in range(n):
        kb = k + 1
        if kb == n:
            kb = 0
        s += P[k, 0] * P[kb, 1] - P[kb, 0] * P[k, 1]
    return 0.5 * s


@wp.func
def sector(p: wp.vec2, q: wp.vec2, r: float) -> float:
    return 0.5 * r * r * wp.atan2(cross2(p, q), wp.dot(p, q))


@wp.func
def circle_triangle(a: wp.vec2, b: wp.vec2, r: float) -> float:
    """Signed area of the disk of radius ``r`` about the origin ∩ the triangle (origin, a, b)."""
    d = b - a
    qa = wp.dot(d, d)
    if qa <= 0.0:
        return 0.0
    qb = wp.dot(a, d)
    qc = wp.dot(a, a) - r * r
    disc = qb * qb - qa * qc
    if disc <= 0.0:
        return sector(a, b, r)
    sq = wp.sqrt(disc)
    t1 = (-qb - sq) / qa
    t2 = (-qb + sq) / qa
    if t2 <= 0.0 or t1 >= 1.0:
        return sector(a, b, r)
    p1 = a + d * wp.max(t1, 0.0)
    p2 = a + d * wp.min(t2, 1.0)
    area = 0.5 * cross2(p1, p2)
    if t1 > 0.0:
        area += sector(a, p1, r)
    if t2 < 1.0:
        area += sector(p2, b, r)
    return area


@wp.func
def beyond_edge_area(a: wp.vec3, b: wp.vec3, ext: wp.vec2, disk: int) -> float:
    """Area of ``R``: the part of the light (centred on the origin; a rect of half extents
    ``ext``, or a disk of radius ``ext.x``) beyond the line ``a b`` from the origin and inside the
    angle ``a b`` subtends there. ``a`` and ``b`` are homogeneous (``x, y, w`` with ``w >= 0``;
    ``w = 0``: a point at infinity, the projection of a point level with the receiver), so the
    half-planes come from products of their coordinates and nothing is divided by a small ``w``."""
    cr = a[0] * b[1] - a[1] * b[0]
    if cr == 0.0:
        return 0.0
    sg = float(1.0)
    if cr < 0.0:
        sg = -1.0
    line = wp.cross(a, b)  # line . (x, y, 1) = 0 through both; its value at the origin is cr
    P = poly_t()
    P[0, 0] = -ext[0]
    P[0, 1] = -ext[1]
    P[1, 0] = ext[0]
    P[1, 1] = -ext[1]
    P[2, 0] = ext[0]
    P[2, 1] = ext[1]
    P[3, 0] = -ext[0]
    P[3, 1] = ext[1]
    n = int(4)
    P, n = clip_half(P, n, wp.vec3(-a[1] * sg, a[0] * sg, 0.0))
    P, n = clip_half(P, n, wp.vec3(b[1] * sg, -b[0] * sg, 0.0))
    P, n = clip_half(P, n, line * (-sg))
    if n < 3:
        return 0.0
    if disk == 0:
        return wp.abs(polygon_area(P, n))
    s = float(0.0)
    for k in range(n):
        kb = k + 1
        if kb == n:
            kb = 0
        s += circle_triangle(wp.vec2(P[k, 0], P[k, 1]), wp.vec2(P[kb, 0], P[kb, 1]), ext[0])
    return wp.abs(s)


@wp.func
def edge_coverage(c: wp.vec3, u: wp.vec3, v: wp.vec3, ext: wp.vec2, disk: int, smax: float, o: wp.vec3, a: wp.vec3, b: wp.vec3) -> float:
    """``|R| / |light|`` for the edge ``a b`` seen from ``o`` (the module docstring); 0 where its
    projection misses the light or the edge lies wholly behind ``o`` or beyond the light."""
    nrm = wp.cross(u, v)
    den = wp.dot(nrm, c - o)
    if den == 0.0 or ext[0] <= 0.0 or ext[1] <= 0.0:
        return 0.0
    # an edge (nearly) through the receiver spans no plane with it: it covers nothing
    pa = a - o
    pb = b - o
    ne = wp.cross(pa, pb)
    if wp.dot(ne, ne) <= 1.0e-12 * wp.dot(pa, pa) * wp.dot(pb, pb):
        return 0.0
    sa = wp.dot(nrm, a - o) / den
    sb = wp.dot(nrm, b - o) / den
    # clip the edge to the slab 0 <= s <= smax (in front of the receiver, before the light); an end
    # left in place keeps its own s (recomputing it from the clip parameter loses a tiny s)
    t0 = float(0.0)
    t1 = float(1.0)
    s0 = sa
    s1 = sb
    ds = sb - sa
    if ds == 0.0:
        if sa < 0.0 or sa > smax:
            return 0.0
    else:
        ta = (0.0 - sa) / ds
        tb = (smax - sa) / ds
        lo_t = wp.min(ta, tb)
        hi_t = wp.max(ta, tb)
        lo_s = smax
        hi_s = float(0.0)
        if ta < tb:
            lo_s = 0.0
            hi_s = smax
        if lo_t > t0:
            t0 = lo_t
            s0 = lo_s
        if hi_t < t1:
            t1 = hi_t
            s1 = hi_s
        if t0 >= t1:
            return 0.0
    s0 = wp.max(s0, 0.0)
    s1 = wp.max(s1, 0.0)
    if s0 == 0.0 and s1 == 0.0:
        return 0.0
    # an end left in place is used as it is (a + (b - a) * 1 can round b's small coordinates away)
    qa = a - o
    if t0 > 0.0:
        qa = a + (b - a) * t0 - o
    qb = b - o
    if t1 < 1.0:
        qb = b + (a - b) * (1.0 - t1) - o
    co = c - o
    cu = wp.dot(co, u)
    cv = wp.dot(co, v)
    scale = wp.max(ext[0], ext[1])
    # a disk's axes scaled apart: an ellipse becomes the unit disk (an affine map keeps the area ratio)
    su = scale
    sv = scale
    if disk != 0:
        su = ext[0]
        sv = ext[1]
    # homogeneous light-plane coordinates about the centre: (q . u - s c_u, q . v - s c_v, s)
    ha = wp.vec3((wp.dot(qa, u) - s0 * cu) / su, (wp.dot(qa, v) - s0 * cv) / sv, s0)
    hb = wp.vec3((wp.dot(qb, u) - s1 * cu) / su, (wp.dot(qb, v) - s1 * cv) / sv, s1)
    e2 = wp.vec2(ext[0] / su, ext[1] / sv)
    area = beyond_edge_area(ha, hb, e2, disk)
    full = 4.0 * e2[0] * e2[1]
    if disk != 0:
        full = wp.pi * e2[0] * e2[0]
    return wp.min(area / full, 1.0)


@wp.kernel
def coverage_kernel(
    L: LightGPU,
    o: wp.array[wp.vec3],
    a: wp.array[wp.vec3],
    b: wp.array[wp.vec3],
    # outputs
    out: wp.array[float],
):
    i = wp.tid()
    c, u, v, ext, disk, smax = light_frame(L, o[i])
    out[i] = edge_coverage(c, u, v, ext, disk, smax, o[i], a[i], b[i])


def edge_coverages(light, o: np.ndarray, a: np.ndarray, b: np.ndarray, scene_diagonal: float = 100.0, device: str = "cpu") -> np.ndarray:
    """[N] ``|R| / |light|`` for receivers ``o`` and edges ``a b`` ([N, 3] each) on the host (tests)."""
    arr = lambda x: wp.array(np.ascontiguousarray(x, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)  # noqa: E731
    out = wp.zeros(len(o), dtype=float, device=device)
    wp.launch(coverage_kernel, dim=len(o), inputs=[light_gpu(light, scene_diagonal), arr(o), arr(a), arr(b)], outputs=[out], device=device)
    return out.numpy()
