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
``R`` empty, which is why only the receivers inside an edge's *wedge* need it. Where the
receiver's tangent plane crosses the light, only the light in front of it counts
(:mod:`wsoft.lightspace.halfspace`): ``R`` is clipped to the plane's line on the light
(:func:`receiver_front`) and :func:`front_coverage` is that part's share of the light.

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

from wsoft.lightspace.halfspace import NO_CLIP, clip_half, front_part, light_area_in, plane_line, square
from wsoft.lightspace.light import LINE_WIDTH, LightGPU, is_round, light_gpu, silhouette_disk, silhouette_ellipse, silhouette_rect

INFINITE = wp.constant(1.0e30)


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
def beyond_edge_area(a: wp.vec3, b: wp.vec3, ext: wp.vec2, disk: int, front: wp.vec3) -> float:
    """Area of ``R`` in front of the receiver's plane: the part of the light (centred on the
    origin; a rect of half extents ``ext``, or a disk of radius ``ext.x``) beyond the line ``a b``
    from the origin, inside the angle ``a b`` subtends there and where ``front . (x, y, 1) >= 0``
    (:func:`~wsoft.lightspace.halfspace.plane_line`). ``a`` and ``b`` are homogeneous (``x, y, w``
    with ``w >= 0``; ``w = 0``: a point at infinity, the projection of a point level with the
    receiver), so the half-planes come from products of their coordinates and nothing is divided
    by a small ``w``."""
    cr = a[0] * b[1] - a[1] * b[0]
    if cr == 0.0:
        return 0.0
    sg = float(1.0)
    if cr < 0.0:
        sg = -1.0
    line = wp.cross(a, b)  # line . (x, y, 1) = 0 through both; its value at the origin is cr
    P, n = square(ext)
    P, n = clip_half(P, n, wp.vec3(-a[1] * sg, a[0] * sg, 0.0))
    P, n = clip_half(P, n, wp.vec3(b[1] * sg, -b[0] * sg, 0.0))
    P, n = clip_half(P, n, line * (-sg))
    P, n = clip_half(P, n, front)
    return light_area_in(P, n, ext, disk)


@wp.func
def coverage_scale(ext: wp.vec2, disk: int) -> wp.vec2:
    """How :func:`edge_coverage` scales the light's plane along ``u`` and ``v``: a rect by its
    larger half extent, a disk by its two semi-axes (an ellipse becomes the unit disk)."""
    if disk != 0:
        return ext
    s = wp.max(ext[0], ext[1])
    return wp.vec2(s, s)


@wp.func
def receiver_front(c: wp.vec3, u: wp.vec3, v: wp.vec3, ext: wp.vec2, disk: int, nrm: wp.vec3, q: wp.vec3) -> wp.vec3:
    """The front side of a receiver's tangent plane (normal ``nrm``, through ``q``) as a line over
    the light's plane in :func:`edge_coverage`'s coordinates (:func:`~wsoft.lightspace.halfspace.plane_line`)."""
    sc = coverage_scale(ext, disk)
    return plane_line(nrm, q, c, u, v, sc[0], sc[1])


@wp.func
def front_coverage(ext: wp.vec2, disk: int, front: wp.vec3) -> float:
    """The fraction of the light in front of ``front`` (:func:`receiver_front`'s line)."""
    sc = coverage_scale(ext, disk)
    if sc[0] <= 0.0 or sc[1] <= 0.0:
        return 1.0
    return front_part(wp.vec2(ext[0] / sc[0], ext[1] / sc[1]), disk, front)


@wp.func
def edge_coverage(c: wp.vec3, u: wp.vec3, v: wp.vec3, ext: wp.vec2, disk: int, smax: float, o: wp.vec3, a: wp.vec3, b: wp.vec3,
                  front: wp.vec3) -> float:
    """``|R| / |light|`` for the edge ``a b`` seen from ``o`` (the module docstring), ``R`` taken
    in front of the line ``front`` (:func:`receiver_front`; :data:`~wsoft.lightspace.halfspace.NO_CLIP`:
    all of it); 0 where its projection misses the light or the edge lies wholly behind ``o`` or
    beyond the light."""
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
    # a disk's axes scaled apart: an ellipse becomes the unit disk (an affine map keeps the area ratio)
    sc = coverage_scale(ext, disk)
    su = sc[0]
    sv = sc[1]
    # homogeneous light-plane coordinates about the centre: (q . u - s c_u, q . v - s c_v, s)
    ha = wp.vec3((wp.dot(qa, u) - s0 * cu) / su, (wp.dot(qa, v) - s0 * cv) / sv, s0)
    hb = wp.vec3((wp.dot(qb, u) - s1 * cu) / su, (wp.dot(qb, v) - s1 * cv) / sv, s1)
    e2 = wp.vec2(ext[0] / su, ext[1] / sv)
    area = beyond_edge_area(ha, hb, e2, disk, front)
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
    out[i] = edge_coverage(c, u, v, ext, disk, smax, o[i], a[i], b[i], NO_CLIP)


def edge_coverages(light, o: np.ndarray, a: np.ndarray, b: np.ndarray, scene_diagonal: float = 100.0, device: str = "cpu") -> np.ndarray:
    """[N] ``|R| / |light|`` for receivers ``o`` and edges ``a b`` ([N, 3] each) on the host (tests)."""
    arr = lambda x: wp.array(np.ascontiguousarray(x, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)  # noqa: E731
    out = wp.zeros(len(o), dtype=float, device=device)
    wp.launch(coverage_kernel, dim=len(o), inputs=[light_gpu(light, scene_diagonal), arr(o), arr(a), arr(b)], outputs=[out], device=device)
    return out.numpy()
