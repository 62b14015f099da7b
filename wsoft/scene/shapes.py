"""UsdGeom's own shapes as polygon meshes, in the prim's local space.

:func:`tessellate` turns a ``UsdGeom.Cube``, ``Sphere``, ``Cylinder``, ``Cone``, ``Capsule``,
``Cylinder_1``, ``Capsule_1`` (where this usd-core has them) or ``Plane`` into points, face counts
and face indices, which the loader then reads exactly as it reads a ``UsdGeom.Mesh``
(:meth:`wsoft.scene.usd_mesh.MeshReader.read_shape`: world transform, time code, materials and
``displayColor``, ``doubleSided``, ``orientation``, instancing). Each shape is the one the schema
defines, centred at the origin, its spine along ``axis`` (``X``, ``Y`` or ``Z``):

- ``Cube``: edges of length ``size``; 8 points, 6 quads (12 triangles).
- ``Sphere``: ``radius``.
- ``Cylinder``: ``radius``, ``height`` along the axis, flat closed ends; ``Cylinder_1``:
  ``radiusBottom`` at -height/2, ``radiusTop`` at +height/2 (a conical frustum).
- ``Cone``: a base of ``radius`` at -height/2, its apex at +height/2.
- ``Capsule``: a cylinder of ``radius`` and ``height`` (the spine without the caps) capped by two
  hemispheres; its length is ``height + 2 radius``. ``Capsule_1``: the frustum of ``radiusBottom`` at
  -height/2 and ``radiusTop`` at +height/2, capped by the two spheres tangent to it there (each
  sphere's radius is its end's radius times sec of the frustum's half-angle, so the surface is C1;
  equal radii give the hemispheres), as ``UsdGeomCapsule_1::ComputeExtent`` bounds it.
- ``Plane``: ``width`` by ``length`` in the plane normal to ``axis`` (axis Z: width along x, length
  along y; Y: x and z; X: z and y), one quad facing +axis. ``doubleSided`` falls back to true for
  a plane (the schema's fallback), to false for the other shapes.

The surfaces of revolution are closed and wound outward (right-handed): a pole (or an end's
centre) fanned to the first ring, quads between rings, the last ring fanned to the other pole.

**Accuracy.** Points lie on the true surface; faces are chords of it. The segment counts keep
every point of the tessellated surface within :data:`SHAPE_TOLERANCE` of the radius of the true
surface, so the silhouette from any direction is within that too (a convex outline lies between
the polyhedron's and the shape's):

- a straight side (cylinder, cone, frustum) has :data:`SEGMENTS_FLAT` segments around, whose
  sagitta ``r (1 - cos(pi / n))`` is at most ``SHAPE_TOLERANCE r``;
- a spherical part (sphere, capsule caps) has :data:`SEGMENTS_CURVED` segments around and
  latitude steps of the same angle ``2 pi / n``: a face's corners lie on a circle of angular radius
  at most ``acos(cos^2(pi / n))``, so the face is at most ``r (1 - cos^2(pi / n)) <= SHAPE_TOLERANCE r``
  inside the sphere.

Both counts are multiples of 4, so rings hold the points at 0, 90, 180 and 270 degrees and the
points' bounding box is the shape's extent (as ``UsdGeom.Boundable.ComputeExtentFromPlugins``
gives it). Triangles: Cube 12, Plane 2, Cylinder 4 x 52 = 208, Cone 2 x 52 = 104, Sphere
72 x 70 = 5040, Capsule 72 x 72 = 5184 (fewer for a ``Capsule_1`` whose caps are not halves).

A negative size, radius, height, width or length, or an axis other than X, Y or Z, is a
:class:`~wsoft.errors.SceneError` naming the file and the prim; a shape with no area (a zero
radius, a zero-size cube) draws nothing, with a warning.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from wsoft.scene.usd_context import StageContext, pxr

SHAPE_TOLERANCE = 0.002
"""The largest distance, as a fraction of the radius (of the larger end radius for a frustum),
between a tessellated shape's surface and the true one: 0.2 %, under a pixel for a shape up to
500 pixels across. Sets :data:`SEGMENTS_FLAT` and :data:`SEGMENTS_CURVED`."""


def _multiple_of_4(x: float) -> int:
    return 4 * math.ceil(x / 4 - 1e-9)


SEGMENTS_FLAT = _multiple_of_4(math.pi / math.acos(1.0 - SHAPE_TOLERANCE))
"""Segments around a straight-sided shape: r (1 - cos(pi / n)) <= SHAPE_TOLERANCE r (52)."""

SEGMENTS_CURVED = _multiple_of_4(math.pi / math.acos(math.sqrt(1.0 - SHAPE_TOLERANCE)))
"""Segments around (and per half turn of latitude, half as many) a spherical part:
r (1 - cos^2(pi / n)) <= SHAPE_TOLERANCE r (72)."""

SHAPE_TYPES = ("Cube", "Sphere", "Cylinder", "Cone", "Capsule", "Cylinder_1", "Capsule_1", "Plane")
"""The UsdGeom schemas :func:`tessellate` reads (``Cylinder_1`` and ``Capsule_1`` where usd-core has them)."""


class ShapeMesh(NamedTuple):
    """A shape as a polygon mesh in its prim's local space."""

    points: np.ndarray  # [V, 3] float64
    counts: np.ndarray  # [F] int64 faceVertexCounts
    indices: np.ndarray  # [sum(counts)] int64 faceVertexIndices
    attrs: tuple  # the attributes that define it (time-sampled ones make it a dynamic caster)


def shape_type(prim) -> str | None:
    """The name of the UsdGeom shape schema ``prim`` is (one of :data:`SHAPE_TYPES`), else None."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    for name in SHAPE_TYPES:
        schema = getattr(UsdGeom, name, None)
        if schema is not None and prim.IsA(schema):
            return name
    return None


def not_drawn(type_name: str) -> str:
    """The warning for a gprim the loader does not draw (curves, points, NURBS patches...)."""
    return (f"{type_name} is not a Mesh or one of UsdGeom's shapes ({', '.join(SHAPE_TYPES)}); ignored "
            "(convert it to a mesh to cast shadows)")


# --------------------------------------------------------------------------- geometry (local space)


def cube(size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cube of edge ``size`` centred at the origin: 8 points, 6 outward quads."""
    h = 0.5 * size
    p = np.array([[x, y, z] for z in (-h, h) for y in (-h, h) for x in (-h, h)], np.float64)
    # corners: index = x + 2 y + 4 z (0: -, 1: +); each face counter-clockwise seen from outside
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return p, np.full(6, 4, np.int64), np.asarray(faces, np.int64).ravel()


def plane(width: float, length: float, axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``width`` x ``length`` quad centred at the origin, normal to ``axis``, facing +axis."""
    w_dir, l_dir = {"X": (2, 1), "Y": (0, 2), "Z": (0, 1)}[axis]
    p = np.zeros((4, 3))
    for i, (a, b) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)]):
        p[i, w_dir] = 0.5 * width * a
        p[i, l_dir] = 0.5 * length * b
    normal = np.cross(p[1] - p[0], p[2] - p[0])
    order = [0, 1, 2, 3] if normal["XYZ".index(axis)] >= 0 else [0, 3, 2, 1]
    return p, np.array([4], np.int64), np.asarray(order, np.int64)


def _latitudes(a0: float, a1: float, step: float) -> np.ndarray:
    """Latitudes from ``a0`` to ``a1`` (both included), no step longer than ``step``, 0 included
    when it lies between them (a sphere's widest ring)."""
    stops = [a0, 0.0, a1] if a0 < 0.0 < a1 else [a0, a1]
    out = [np.array([a0])]
    for s, e in zip(stops[:-1], stops[1:]):
        k = max(1, math.ceil((e - s) / step - 1e-9))
        out.append(s + (e - s) * np.arange(1, k + 1) / k)
    return np.concatenate(out)


def capsule_profile(radius_bottom: float, radius_top: float, height: float) -> list[tuple[float, float]]:
    """The (radius, z) outline of a ``Capsule_1`` (a ``Capsule`` with equal radii; a sphere for
    height 0 and equal radii), bottom pole to top pole: the bottom sphere up to its tangent ring
    (radius_bottom at -height/2), the frustum, the top sphere from its tangent ring (radius_top at
    +height/2)."""
    slope = (radius_bottom - radius_top) / height if height > 0 else 0.0
    sec = math.sqrt(1.0 + slope * slope)
    rb, rt = radius_bottom * sec, radius_top * sec  # the end spheres' radii
    cb, ct = -0.5 * height - slope * radius_bottom, 0.5 * height - slope * radius_top  # their centres
    phi = math.atan(slope)  # the latitude of both tangent rings
    step = 2.0 * math.pi / SEGMENTS_CURVED
    prof = [(0.0, cb - rb)]
    prof += [(rb * math.cos(a), cb + rb * math.sin(a)) for a in _latitudes(-0.5 * math.pi, phi, step)[1:]]
    prof[-1] = (radius_bottom, -0.5 * height)  # the tangent ring, exactly
    top = [(rt * math.cos(a), ct + rt * math.sin(a)) for a in _latitudes(phi, 0.5 * math.pi, step)[:-1]]
    top[0] = (radius_top, 0.5 * height)
    return prof + top + [(0.0, ct + rt)]


def revolve(profile, segments: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The surface swept by the (radius, z) ``profile`` about +z, ``segments`` around: the profile
    runs from a point on the axis to a point on the axis (the solid on its left going up the
    outside), repeated points dropped. Points: the two poles and one ring per profile point between;
    faces: triangle fans at the poles, quads between rings, wound outward. Empty when no ring is
    left (a zero radius)."""
    tol = 1e-12 * max(abs(v) for rz in profile for v in rz)  # float64 noise at the shape's size
    prof = []
    for r, z in profile:
        if not prof or abs(r - prof[-1][0]) > tol or abs(z - prof[-1][1]) > tol:
            prof.append((float(r), float(z)))
    rings = prof[1:-1]
    if not rings or all(r == 0.0 for r, _ in rings):
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    n = segments
    t = 2.0 * math.pi * np.arange(n) / n
    c, s = np.cos(t), np.sin(t)
    c[n // 4::n // 2] = 0.0  # exact zeros at 90 and 270 degrees (n is a multiple of 4)
    s[0::n // 2] = 0.0
    pts = [np.array([[0.0, 0.0, prof[0][1]]])]
    pts += [np.stack([r * c, r * s, np.full(n, z)], axis=1) for r, z in rings]
    pts.append(np.array([[0.0, 0.0, prof[-1][1]]]))
    p = np.concatenate(pts)
    j, k = np.arange(n), (np.arange(n) + 1) % n
    top = 1 + len(rings) * n
    counts = [np.full(n, 3)]
    faces = [np.stack([np.zeros(n, np.int64), 1 + k, 1 + j], axis=1).ravel()]  # bottom pole fan
    for i in range(len(rings) - 1):
        a, b = 1 + i * n, 1 + (i + 1) * n
        counts.append(np.full(n, 4))
        faces.append(np.stack([a + j, a + k, b + k, b + j], axis=1).ravel())
    a = 1 + (len(rings) - 1) * n
    counts.append(np.full(n, 3))
    faces.append(np.stack([a + j, a + k, np.full(n, top)], axis=1).ravel())  # top pole fan
    return p, np.concatenate(counts).astype(np.int64), np.concatenate(faces).astype(np.int64)


def along_axis(p: np.ndarray, axis: str) -> np.ndarray:
    """Points built with their spine along +z, turned so it runs along ``axis`` (a rotation, as
    USD's imaging does: x, y, z become y, z, x for X and z, x, y for Y)."""
    if axis == "X":
        return p[:, [2, 0, 1]]
    if axis == "Y":
        return p[:, [1, 2, 0]]
    return p


# --------------------------------------------------------------------------- prims


def tessellate(ctx: StageContext, prim, kind: str | None = None) -> ShapeMesh | None:
    """The shape ``prim`` (of type ``kind``, one of :data:`SHAPE_TYPES`; found when None) at the
    context's time code as a :class:`ShapeMesh`; None, with a warning, when it has no area. Bad
    attribute values raise :class:`~wsoft.errors.SceneError` (naming the file and the prim)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    kind = kind or shape_type(prim)
    schema = getattr(UsdGeom, kind)(prim)
    attrs = []

    def value(name: str) -> float:
        attr = getattr(schema, f"Get{name[0].upper()}{name[1:]}Attr")()
        attrs.append(attr)
        return ctx.size(prim, name, ctx.get(attr))

    def axis() -> str:
        attr = schema.GetAxisAttr()
        attrs.append(attr)
        a = str(ctx.get(attr, "Z"))
        if a not in ("X", "Y", "Z"):
            raise ctx.err(prim, f"axis = {a!r} is not X, Y or Z")
        return a

    if kind == "Cube":
        size = value("size")
        p, counts, idx = cube(size)
        empty = size == 0.0
    elif kind == "Plane":
        w, l, ax = value("width"), value("length"), axis()
        p, counts, idx = plane(w, l, ax)
        empty = w == 0.0 or l == 0.0
    else:
        if kind == "Sphere":
            r = value("radius")
            prof, segments, ax = capsule_profile(r, r, 0.0), SEGMENTS_CURVED, "Z"
        elif kind in ("Cylinder", "Cone"):
            h, r, ax = value("height"), value("radius"), axis()
            prof = [(0.0, -0.5 * h), (r, -0.5 * h), (0.0 if kind == "Cone" else r, 0.5 * h), (0.0, 0.5 * h)]
            segments = SEGMENTS_FLAT
        elif kind == "Cylinder_1":
            h, rt, rb, ax = value("height"), value("radiusTop"), value("radiusBottom"), axis()
            prof, segments = [(0.0, -0.5 * h), (rb, -0.5 * h), (rt, 0.5 * h), (0.0, 0.5 * h)], SEGMENTS_FLAT
        elif kind == "Capsule":
            h, r, ax = value("height"), value("radius"), axis()
            prof, segments = capsule_profile(r, r, h), SEGMENTS_CURVED
        else:  # Capsule_1
            h, rt, rb, ax = value("height"), value("radiusTop"), value("radiusBottom"), axis()
            prof, segments = capsule_profile(rb, rt, h), SEGMENTS_CURVED
        p, counts, idx = revolve(prof, segments)
        p = along_axis(p, ax)
        empty = len(counts) == 0
    if empty:
        ctx.warn(prim, f"{kind} has no area ({', '.join(f'{a.GetName()} = {ctx.get(a)}' for a in attrs)}); nothing drawn")
        return None
    return ShapeMesh(points=p, counts=counts, indices=idx, attrs=tuple(attrs))
