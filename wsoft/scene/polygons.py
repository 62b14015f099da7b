"""Polygon faces -> triangles, as a mesh's ``faceVertexCounts`` and ``faceVertexIndices`` give them.

:func:`triangulate` fans every face from its first corner, ``(c0, ci, ci+1)`` for ``i = 1 .. n-2``,
wherever that fan is a triangulation of the face: every fan triangle turns the face's way (about
its Newell normal, the face's vector area) and together they sweep less than a full turn about
``c0``. That holds for every convex face (so triangles, convex quads and convex n-gons keep the fan
triangles in the fan order), and for a concave face whose first corner sees all of it. The test
runs in numpy over all faces at once.

Any other face is concave (or worse) and goes one by one through :func:`ear_clip` on its
best-fit plane (the plane through its centroid normal to its Newell normal): its triangles
replace its fan triangles, in the same place in the face order. A face whose outline, projected
onto that plane, crosses itself (or that has no best-fit plane: its vector area is zero while its
triangles are not) has no one triangulation: it keeps the fan and is counted in
:attr:`Triangles.self_intersecting`; an ear-clipped face farther from its plane than
:data:`NON_PLANAR` of its size is counted in :attr:`Triangles.non_planar`.

Every triangle is wound as the face is (counter-clockwise about the face's normal); corners are
face-vertex indices (positions in ``faceVertexIndices``), so face-varying primvars read them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NON_PLANAR = 1e-3
"""An ear-clipped face whose corners lie farther than this fraction of its size (its bounding box
diagonal) from its best-fit plane is counted as non-planar."""

_DEGENERATE = 1e-10  # float64 noise: a corner whose angle's sine (or whose 2-D turn, over the outline's size squared) is below this is straight


@dataclass
class Triangles:
    """The triangles of a mesh's faces."""

    corners: np.ndarray
    """[T, 3] int64: face-vertex (corner) indices of each triangle, wound as its face."""
    faces: np.ndarray
    """[T] int64: the face of each triangle (faces in order; a face's triangles together)."""
    ear_clipped: int = 0
    """Faces whose fan is not a triangulation of them, ear-clipped."""
    non_planar: int = 0
    """Ear-clipped faces farther than :data:`NON_PLANAR` of their size from their best-fit plane."""
    off_plane: float = 0.0
    """The largest distance of those faces' corners from their planes (the points' units)."""
    self_intersecting: int = 0
    """Faces whose projected outline crosses itself (or with no best-fit plane): fan-triangulated."""


def fan(counts: np.ndarray, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The fan triangles ``(c0, ci, ci+1)`` of the faces with ``counts`` corners (those of three
    or more, and with ``keep`` only the faces it marks): their corners [T, 3] and faces [T]."""
    counts = np.asarray(counts, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else np.zeros(0, np.int64)
    ntri = np.maximum(counts - 2, 0)
    if keep is not None:
        ntri = np.where(keep, ntri, 0)
    faces = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    c0 = starts[faces]
    return np.stack([c0, c0 + k + 1, c0 + k + 2], axis=1), faces


def triangulate(points: np.ndarray, counts: np.ndarray, indices: np.ndarray, keep: np.ndarray | None = None) -> Triangles:
    """The triangles of the faces (``counts`` corners each, ``indices`` into ``points`` [V, 3]);
    with ``keep`` ([F] bool) only those of the faces it marks. See the module's docstring."""
    counts = np.asarray(counts, np.int64)
    p, idx = np.asarray(points, np.float64), np.asarray(indices, np.int64)  # float32 points: their products stay finite
    corners, faces = fan(counts, keep)
    out = Triangles(corners, faces)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else np.zeros(0, np.int64)
    live = counts >= 4 if keep is None else (counts >= 4) & keep
    quads = np.flatnonzero(live & (counts == 4))
    more = np.flatnonzero(live & (counts > 4))
    faces_bad, areas_bad = np.zeros(0, np.int64), np.zeros((0, 3))
    if len(quads):
        bad, area = _quad_fans_fail(p, idx, starts[quads])
        faces_bad, areas_bad = quads[bad], area[bad]
    if len(more):
        mask = np.zeros(len(counts), bool)
        mask[more] = True
        sel = mask[faces]
        bad, area = _fans_fail(p, idx, corners[sel], faces[sel])
        faces_bad, areas_bad = np.concatenate([faces_bad, more[bad]]), np.concatenate([areas_bad, area[bad]])
    if not len(faces_bad):
        return out
    new_corners, new_faces, drop = [], [], np.zeros(len(counts), bool)
    for f, a in zip(faces_bad, areas_bad):
        s0, n = int(starts[f]), int(counts[f])
        v = p[idx[s0:s0 + n]]
        size = float(np.linalg.norm(np.ptp(v, axis=0)))
        norm = float(np.linalg.norm(a))
        if norm <= _DEGENERATE * size * size:  # no best-fit plane (a symmetric bow tie)
            out.self_intersecting += 1
            continue
        nrm = a / norm
        u = np.cross(nrm, [1.0, 0.0, 0.0] if abs(nrm[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(nrm, u)  # (u, w, nrm) right-handed: the face runs counter-clockwise in (u, w)
        rel = v - v.mean(axis=0)
        xy = np.stack([rel @ u, rel @ w], axis=1)
        local = ear_clip(xy) if not crosses_itself(xy) else None
        if local is None:
            out.self_intersecting += 1
            continue
        off = float(np.abs(rel @ nrm).max())
        if off > NON_PLANAR * size:
            out.non_planar += 1
            out.off_plane = max(out.off_plane, off)
        out.ear_clipped += 1
        drop[f] = True
        new_corners.append(s0 + np.asarray(local, np.int64).reshape(-1, 3))
        new_faces.append(np.full(len(local), f, np.int64))
    if drop.any():
        kept = ~drop[faces]
        corners = np.concatenate([corners[kept], *new_corners])
        faces = np.concatenate([faces[kept], *new_faces])
        order = np.argsort(faces, kind="stable")  # face order; within a face, its own order
        out.corners, out.faces = corners[order], faces[order]
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _turns(cr: np.ndarray, area: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Does each fan triangle (twice its vector area ``cr``, its edges ``e1``, ``e2`` from the
    face's first corner) turn the face's way (``area``: the face's vector area) or have no area;
    and has it none (a straight angle at the first corner, or a repeated corner)?"""
    straight = _dot(cr, cr) <= _DEGENERATE**2 * _dot(e1, e1) * _dot(e2, e2)
    return straight | (_dot(cr, area) > 0), straight


def _quad_fans_fail(p: np.ndarray, idx: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For quads (their first corners ``starts``): is the fan (c0, c1, c2), (c0, c2, c3) not a
    triangulation (a triangle turns against the quad)? And each quad's vector area (x2)."""
    c = idx[starts[:, None] + np.arange(4)]
    a = p[c[:, 0]]
    e1, e2, e3 = p[c[:, 1]] - a, p[c[:, 2]] - a, p[c[:, 3]] - a
    cr0, cr1 = _cross(e1, e2), _cross(e2, e3)
    area = cr0 + cr1
    t0, s0 = _turns(cr0, area, e1, e2)
    t1, s1 = _turns(cr1, area, e2, e3)
    # (two triangles, each under a half turn at c0, never sweep a full turn; a quad with no
    # triangle of any area has no other triangulation to find)
    return ~(t0 & t1) & ~(s0 & s1), area


def _fans_fail(p: np.ndarray, idx: np.ndarray, corners: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For faces of five or more corners (their fan triangles ``corners``, ``faces``, each face's
    together): is the fan not a triangulation (a triangle turns against the face, or the
    triangles sweep a full turn about c0)? And each face's vector area (x2)."""
    start = np.concatenate([[True], faces[1:] != faces[:-1]])
    first = np.flatnonzero(start)
    group = np.cumsum(start) - 1
    a = p[idx[corners[:, 0]]]
    e1, e2 = p[idx[corners[:, 1]]] - a, p[idx[corners[:, 2]]] - a
    cr = _cross(e1, e2)
    area = np.add.reduceat(cr, first, axis=0)
    turns, straight = _turns(cr, area[group], e1, e2)
    sweep = np.add.reduceat(np.arctan2(np.sqrt(_dot(cr, cr)), _dot(e1, e2)), first)
    ok = np.logical_and.reduceat(turns, first) & (sweep < 2 * np.pi * (1 - 1e-9))
    return ~ok & ~np.logical_and.reduceat(straight, first), area


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Twice the signed area of triangles (a, b, c) in 2-D (positive: counter-clockwise)."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def crosses_itself(xy: np.ndarray, chunk: int = 512) -> bool:
    """Does the closed outline ``xy`` [n, 2] have two non-adjacent edges that cross (properly:
    each edge's ends strictly on either side of the other's line)? Edges that only touch (a
    slit joining a hole to the outline) do not count."""
    n = len(xy)
    if n < 4:
        return False
    a, b = xy, np.roll(xy, -1, axis=0)
    tol = _DEGENERATE * float(np.ptp(xy, axis=0).max()) ** 2
    sgn = lambda v: np.where(v > tol, 1, np.where(v < -tol, -1, 0))  # noqa: E731
    j = np.arange(n)
    for i0 in range(0, n, chunk):
        i = np.arange(i0, min(n, i0 + chunk))[:, None]
        ai, bi = a[i], b[i]
        d1, d2 = sgn(_orient(ai, bi, a[None])), sgn(_orient(ai, bi, b[None]))
        d3, d4 = sgn(_orient(a[None], b[None], ai)), sgn(_orient(a[None], b[None], bi))
        far = (np.abs(i - j[None]) > 1) & (np.abs(i - j[None]) < n - 1)  # not the same or adjacent edges
        if np.any(far & (d1 * d2 < 0) & (d3 * d4 < 0)):
            return True
    return False


def ear_clip(xy: np.ndarray) -> list[tuple[int, int, int]] | None:
    """Triangles (indices into ``xy``) of the simple polygon ``xy`` [n, 2], counter-clockwise:
    each time the first corner that is convex and holds no other corner inside or on its
    triangle (an ear) is cut off. A corner on a straight line through its neighbours (or a
    repeated one) is dropped without a triangle. None when no ear is found (not a simple polygon)."""
    tol = _DEGENERATE * float(np.ptp(xy, axis=0).max()) ** 2
    rem = list(range(len(xy)))
    out: list[tuple[int, int, int]] = []
    while len(rem) > 3:
        P = xy[rem]
        prev, nxt = np.roll(P, 1, axis=0), np.roll(P, -1, axis=0)
        turn = _orient(prev, P, nxt)
        straight = np.flatnonzero(np.abs(turn) <= tol)
        if len(straight):
            rem.pop(int(straight[0]))
            continue
        reflex = np.flatnonzero(turn < 0)
        m = len(rem)
        for i in np.flatnonzero(turn > 0):
            a, b, c = prev[i], P[i], nxt[i]
            r = P[reflex]
            at_corner = (r == a).all(axis=1) | (r == b).all(axis=1) | (r == c).all(axis=1)
            inside = (_orient(a, b, r) >= -tol) & (_orient(b, c, r) >= -tol) & (_orient(c, a, r) >= -tol) & ~at_corner
            if not inside.any():
                out.append((rem[i - 1], rem[i], rem[(i + 1) % m]))
                rem.pop(int(i))
                break
        else:
            return None
    if len(rem) == 3 and abs(float(_orient(xy[rem[0]], xy[rem[1]], xy[rem[2]]))) > tol:
        out.append((rem[0], rem[1], rem[2]))
    return out
