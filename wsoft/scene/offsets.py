"""Where a ray that leaves a surface starts: a few float32 ulps off the surface, never a scene-sized epsilon.

A point on a triangle computed from its corners (barycentric weights) is within a few ulps of the
triangle's plane; a ray from it that Warp's watertight test (``intersect_ray_tri_woop``) checks
against that triangle again meets it at a ``t`` whose rounding error is a few ulps of the corners'
coordinates relative to the origin. So a ray leaves a surface from the point moved along the
surface's normal, to the side it goes, by :data:`OFFSET_ULPS` float32 ulps of the larger of the
point's and its triangle's largest coordinate (:func:`offset_origin`): as pbrt-v4's error bounds
(``gamma(7)`` times the corners' magnitudes) and Wächter & Binder ("A Fast and Robust Method for
Avoiding Self-Intersection", Ray Tracing Gems ch. 6) do, scaled to the coordinates and so the same
at every scene size (a scene 1e-12 across and one 1e7 across alike). Measured on a 12 x 12 ground
triangle pair tilted 0 to 63 degrees, centred on the origin and 1000 units off it, and on one 1e-9
across, with 200,000 rays each, mostly grazing: 4 ulps of the corners already never met the
triangle again, 16 ulps of the point alone did (1 in 10,000 near the origin); 16 ulps of the corners
are kept. Every pass that starts a ray on a surface (the eye ray's walk past culled faces and
cutout holes, the shadow rays from G-buffer samples) uses these functions.
"""

from __future__ import annotations

import warp as wp

OFFSET_ULPS = 16.0  # float32 ulps (of the largest coordinate) a ray's origin moves off its surface
FLOAT32_EPSILON = 1.1920929e-7  # 2^-23: one ulp of a float32 in [1, 2); at most 2 ulps of any float32 in relative terms
OFFSET_RELATIVE = wp.constant(OFFSET_ULPS * FLOAT32_EPSILON)


@wp.func
def coordinate_scale(p: wp.vec3) -> float:
    """The largest absolute coordinate of ``p``."""
    return wp.max(wp.abs(p[0]), wp.max(wp.abs(p[1]), wp.abs(p[2])))


@wp.func
def triangle_scale(a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """The largest absolute coordinate of a triangle's corners: what the rounding of a point on it,
    and of a ray test against it, is a few ulps of."""
    return wp.max(coordinate_scale(a), wp.max(coordinate_scale(b), coordinate_scale(c)))


@wp.func
def ray_offset(p: wp.vec3, scale: float) -> float:
    """How far a ray's origin moves off the surface at ``p``: :data:`OFFSET_ULPS` ulps of the larger
    of ``p``'s largest coordinate and ``scale`` (the coordinates of the triangle ``p`` lies on,
    :func:`triangle_scale`)."""
    return OFFSET_RELATIVE * wp.max(coordinate_scale(p), scale)


@wp.func
def offset_origin(p: wp.vec3, n: wp.vec3, scale: float) -> wp.vec3:
    """``p`` moved :func:`ray_offset` along the unit normal ``n`` (pointing to the side the ray leaves to)."""
    return p + n * ray_offset(p, scale)


@wp.func
def mesh_hit(mesh: wp.uint64, face: int, u: float, v: float):
    """A ray's hit on triangle ``face`` of ``mesh`` at Warp's weights (``u``, ``v``: p = p0 u + p1 v +
    p2 (1 - u - v)), in the mesh's frame: (the point from the corners, the triangle's
    :func:`triangle_scale`, its unit geometric normal; zero for a degenerate triangle)."""
    m = wp.mesh_get(mesh)
    a = m.points[m.indices[3 * face + 0]]
    b = m.points[m.indices[3 * face + 1]]
    c = m.points[m.indices[3 * face + 2]]
    e1 = b - a
    e2 = c - a
    big = wp.max(wp.max(wp.max(wp.abs(e1[0]), wp.abs(e1[1])), wp.max(wp.abs(e1[2]), wp.abs(e2[0]))), wp.max(wp.abs(e2[1]), wp.abs(e2[2])))
    n = wp.vec3(0.0)
    if big > 0.0:
        n = wp.normalize(wp.cross(e1 / big, e2 / big))  # edges scaled to unit size first: no underflow on tiny triangles
    return a * u + b * v + c * (1.0 - u - v), triangle_scale(a, b, c), n


@wp.func
def step_past(mesh: wp.uint64, face: int, u: float, v: float, o: wp.vec3, dir: wp.vec3):
    """A ray o + t*dir that met triangle ``face`` of ``mesh`` (at ``u``, ``v``) and goes on past it:
    (its new origin, the hit point moved :func:`ray_offset` to the far side of the triangle's plane,
    and how far along ``dir``, in units of t, that lies from ``o``). ``dir`` need not be unit length
    (an instance's frame keeps the world's t)."""
    p, s, n = mesh_hit(mesh, face, u, v)
    side = n
    if wp.dot(n, dir) < 0.0:
        side = -n
    if wp.length_sq(n) == 0.0:  # a triangle too thin for a normal: on along the ray
        side = wp.normalize(dir)
    q = offset_origin(p, side, s)
    return q, wp.dot(q - o, dir) / wp.dot(dir, dir)
