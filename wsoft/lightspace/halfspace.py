"""A light clipped to a receiver's half-space: the part of a light in front of a receiver's tangent
plane, the only part that can light it (:func:`~wsoft.lightspace.light.in_front`).

The reference counts a light sample only where its ray leaves the receiver's visible side, and
divides by all the samples: ``V`` is the visible area of the light *in front of the receiver's
plane* over the *whole* light's area. A light that crosses the plane (a wall under a larger ceiling
light, the side of a box) lights the receiver with its front part alone, and an occluder over that
part shadows it however open the part behind is. Every technique that integrates or filters over
the light works on the front part:

- the plane as a line over the light's own 2D coordinates (:func:`plane_line`): ``h . (x, y, 1) >= 0``
  holds for the light points in front (the light's plane meets the receiver's plane in a line);
- a convex polygon clipped to such a line (:func:`clip_half`, Sutherland-Hodgman), its area
  (:func:`polygon_area`), and a disk's area inside a convex polygon (:func:`disk_in_polygon`,
  exact: a sum of disk ∩ triangle terms of triangles and circular sectors);
- the fraction of a rect or disk light in front (:func:`front_part`), and for filters that query a
  rectangle of the light (a summed-area table, a kernel window) the bounding rectangle of the
  front part in the light's normalised coordinates with that fraction (:func:`front_window`): a
  filter over that window times the fraction is the front part's visible fraction over the whole
  light, exactly where the front part is its own bounding rectangle (a rect light cut along one of
  its axes) and approximately elsewhere.

Light coordinates: ``x, y`` in ``[-1, 1]^2`` over a rect light's half extents (or over any scaled
square, as :mod:`~wsoft.lightspace.coverage` uses them), the unit disk over a disk-shaped light's
semi-axes (an affine map: area ratios are kept).
"""

from __future__ import annotations

import warp as wp

from wsoft.lightspace.light import LightKernel
from wsoft.lightspace.view import ViewGPU

poly_t = wp.types.matrix(shape=(8, 2), dtype=wp.float32)  # a convex polygon: a rectangle clipped by at most 4 lines
NO_CLIP = wp.constant(wp.vec3(0.0, 0.0, 1.0))  # a line every point lies in front of: nothing clipped


@wp.func
def cross2(a: wp.vec2, b: wp.vec2) -> float:
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def plane_line(nrm: wp.vec3, q: wp.vec3, c: wp.vec3, u: wp.vec3, v: wp.vec3, su: float, sv: float) -> wp.vec3:
    """The half-space ``nrm . (X - q) >= 0`` (a receiver's front side: normal ``nrm``, through
    ``q``) over the light points ``X = c + x su u + y sv v``: ``h`` with ``h . (x, y, 1) >= 0`` in
    front."""
    return wp.vec3(su * wp.dot(nrm, u), sv * wp.dot(nrm, v), wp.dot(nrm, c - q))


@wp.func
def square(ext: wp.vec2):
    """The rectangle ``[-ext.x, ext.x] x [-ext.y, ext.y]``, counter-clockwise: (polygon, 4)."""
    P = poly_t()
    P[0, 0] = -ext[0]
    P[0, 1] = -ext[1]
    P[1, 0] = ext[0]
    P[1, 1] = -ext[1]
    P[2, 0] = ext[0]
    P[2, 1] = ext[1]
    P[3, 0] = -ext[0]
    P[3, 1] = ext[1]
    return P, int(4)


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
def disk_in_polygon(P: poly_t, n: int, r: float) -> float:
    """Area of the disk of radius ``r`` about the origin inside the convex polygon ``P[:n]``."""
    s = float(0.0)
    for k in range(n):
        kb = k + 1
        if kb == n:
            kb = 0
        s += circle_triangle(wp.vec2(P[k, 0], P[k, 1]), wp.vec2(P[kb, 0], P[kb, 1]), r)
    return wp.abs(s)


@wp.func
def light_area_in(P: poly_t, n: int, ext: wp.vec2, disk: int) -> float:
    """Area of the light (the rectangle ``±ext``, or the disk of radius ``ext.x``) inside the convex
    polygon ``P[:n]``, which lies within the light's bounding rectangle."""
    if n < 3:
        return 0.0
    if disk == 0:
        return wp.abs(polygon_area(P, n))
    return disk_in_polygon(P, n, ext[0])


@wp.func
def front_part(ext: wp.vec2, disk: int, h: wp.vec3) -> float:
    """The fraction of the light (the rectangle ``±ext``, or the disk of radius ``ext.x``) where
    ``h . (x, y, 1) >= 0``: exactly 1 where the line misses it on the front side, 0 on the back."""
    reach = wp.abs(h[0]) * ext[0] + wp.abs(h[1]) * ext[1]
    if disk != 0:
        reach = wp.sqrt(h[0] * h[0] + h[1] * h[1]) * ext[0]
    if h[2] >= reach:
        return 1.0
    if h[2] <= -reach:
        return 0.0
    if disk != 0:  # a circular segment, in closed form: the signed distance of the centre from the line
        ln = wp.sqrt(h[0] * h[0] + h[1] * h[1])
        if ln <= 0.0:
            return wp.where(h[2] >= 0.0, 1.0, 0.0)
        d = wp.clamp(h[2] / (ln * ext[0]), -1.0, 1.0)
        return (wp.acos(-d) + d * wp.sqrt(wp.max(1.0 - d * d, 0.0))) / wp.pi
    full = 4.0 * ext[0] * ext[1]
    if full <= 0.0:
        return 1.0
    P, n = square(ext)
    P, n = clip_half(P, n, h)
    return wp.min(light_area_in(P, n, ext, disk) / full, 1.0)


@wp.func
def front_window(disk: int, h: wp.vec3) -> wp.vec4:
    """The bounding rectangle ``(x0, y0, x1, y1)`` of the part of the light in front of ``h`` (light
    coordinates: ``[-1, 1]^2``, or the unit disk for a disk-shaped light); ``x0 > x1`` when no
    part is in front. :func:`front_part` (with ``ext = (1, 1)``) is that part's fraction of the light."""
    x0 = float(1.0e30)
    y0 = float(1.0e30)
    x1 = float(-1.0e30)
    y1 = float(-1.0e30)
    if disk == 0:
        P, n = square(wp.vec2(1.0, 1.0))
        P, n = clip_half(P, n, h)
        for k in range(n):
            x0 = wp.min(x0, P[k, 0])
            x1 = wp.max(x1, P[k, 0])
            y0 = wp.min(y0, P[k, 1])
            y1 = wp.max(y1, P[k, 1])
        return wp.vec4(x0, y0, x1, y1)
    # the unit disk: its four extreme points that lie in front, and the chord's ends
    for k in range(4):
        ex = float(0.0)
        ey = float(0.0)
        if k == 0:
            ex = 1.0
        elif k == 1:
            ex = -1.0
        elif k == 2:
            ey = 1.0
        else:
            ey = -1.0
        if h[0] * ex + h[1] * ey + h[2] >= 0.0:
            x0 = wp.min(x0, ex)
            x1 = wp.max(x1, ex)
            y0 = wp.min(y0, ey)
            y1 = wp.max(y1, ey)
    ln2 = h[0] * h[0] + h[1] * h[1]
    if ln2 > 0.0:
        ln = wp.sqrt(ln2)
        d = -h[2] / ln  # the chord's distance from the centre along the line's normal
        if d * d < 1.0:
            nx = h[0] / ln
            ny = h[1] / ln
            w = wp.sqrt(1.0 - d * d)
            for sgn in range(2):
                s = w * (2.0 * float(sgn) - 1.0)
                px = d * nx - s * ny
                py = d * ny + s * nx
                x0 = wp.min(x0, px)
                x1 = wp.max(x1, px)
                y0 = wp.min(y0, py)
                y1 = wp.max(y1, py)
    return wp.vec4(x0, y0, x1, y1)


@wp.func
def view_front_line(lv: ViewGPU, k: LightKernel, pv: wp.vec3, nv: wp.vec3) -> wp.vec3:
    """The front of a receiver (view-space point ``pv``, view-space normal ``nv``) as a line over
    the light's normalised coordinates ``(x, y)`` of a light view ``lv`` with the kernel ``k``: a
    local light's points ``(x k.half.x, y k.half.y, 0)`` about the view's origin (its centre), a
    distant light's directions ``(x t, y t, -1)`` (:func:`plane_line`)."""
    if lv.persp != 0:
        return wp.vec3(k.half[0] * nv[0], k.half[1] * nv[1], -wp.dot(nv, pv))
    return wp.vec3(k.half[0] * nv[0], k.half[1] * nv[1], -nv[2])


@wp.func
def box_in_front(lo: wp.vec2, hi: wp.vec2, h: wp.vec3) -> float:
    """The share of the light square ``[-1, 1]^2`` covered by the rectangle ``[lo, hi]`` in front of
    ``h``."""
    x0 = wp.max(lo[0], -1.0)
    y0 = wp.max(lo[1], -1.0)
    x1 = wp.min(hi[0], 1.0)
    y1 = wp.min(hi[1], 1.0)
    if x1 <= x0 or y1 <= y0:
        return 0.0
    P, n = square(wp.vec2(0.5 * (x1 - x0), 0.5 * (y1 - y0)))
    cx = 0.5 * (x0 + x1)
    cy = 0.5 * (y0 + y1)
    P, n = clip_half(P, n, wp.vec3(h[0], h[1], h[2] + h[0] * cx + h[1] * cy))  # the box about its centre
    if n < 3:
        return 0.0
    return 0.25 * wp.abs(polygon_area(P, n))


@wp.func
def kernel_front(lv: ViewGPU, k: LightKernel, pv: wp.vec3, nv: wp.vec3):
    """A filter kernel shaped like the light (:class:`~wsoft.lightspace.light.LightKernel`, over a
    light view ``lv`` whose origin is a local light's centre, or along a distant light's direction)
    clipped to the front of a receiver at view-space point ``pv`` of view-space normal ``nv``: (the
    kernel's new centre as a multiple of its half-size, its new half-size as a multiple, the front
    part's fraction of the light). A light sample at light coordinates ``(x, y)`` is seen through
    the kernel at the same multiple ``(x, y)`` of its half-size, so a filter over the window times
    the fraction is the front part's visible fraction over the whole light
    (:func:`front_window`). A light wholly in front gives ``((0, 0), (1, 1), 1)`` exactly; one wholly
    behind a fraction of 0."""
    h = view_front_line(lv, k, pv, nv)
    reach = wp.abs(h[0]) + wp.abs(h[1])
    if k.disk != 0:
        reach = wp.sqrt(h[0] * h[0] + h[1] * h[1])
    if h[2] >= reach:
        return wp.vec2(0.0, 0.0), wp.vec2(1.0, 1.0), 1.0
    if h[2] <= -reach:
        return wp.vec2(0.0, 0.0), wp.vec2(0.0, 0.0), 0.0
    frac = front_part(wp.vec2(1.0, 1.0), k.disk, h)
    w = front_window(k.disk, h)
    if frac <= 0.0 or w[0] > w[2] or w[1] > w[3]:
        return wp.vec2(0.0, 0.0), wp.vec2(0.0, 0.0), 0.0
    return wp.vec2(0.5 * (w[0] + w[2]), 0.5 * (w[1] + w[3])), wp.vec2(0.5 * (w[2] - w[0]), 0.5 * (w[3] - w[1])), frac


@wp.func
def front_box(tc: wp.vec2, half: wp.vec2, mid: wp.vec2, hs: wp.vec2, least: float) -> wp.vec4:
    """The box ``(x0, x1, y0, y1)`` of a light-shaped kernel of half-size ``half`` about ``tc``
    clipped to a receiver's front window (:func:`kernel_front`'s ``mid`` and ``hs``), at least
    ``least`` wide each way about its centre where the window shrinks it (a kernel of the whole
    light is returned as it is)."""
    cx = tc[0] + mid[0] * half[0]
    cy = tc[1] + mid[1] * half[1]
    hx = wp.where(hs[0] < 1.0, wp.max(half[0] * hs[0], least), half[0])
    hy = wp.where(hs[1] < 1.0, wp.max(half[1] * hs[1], least), half[1])
    return wp.vec4(cx - hx, cx + hx, cy - hy, cy + hy)
