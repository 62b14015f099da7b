"""Mesh primitives as plain arrays: a :data:`MeshData` is ``(points, counts, indices)``.

``points`` is ``(N, 3)`` float64, ``counts`` the vertex count of each face and ``indices`` the
face-vertex indices. Closed meshes are wound counter-clockwise seen from outside (normals out).
Nothing here touches USD: :func:`wsoft.stages.add_mesh` writes a mesh onto a stage.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

MeshData = tuple[np.ndarray, list[int], list[int]]


def box_mesh(lo: Sequence[float], hi: Sequence[float]) -> MeshData:
    """Axis-aligned box as 6 outward-facing quads (8 shared points)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    pts = np.empty((8, 3), dtype=np.float64)
    for i in range(8):  # bit 0 -> x, bit 1 -> y, bit 2 -> z
        pts[i] = [hi[0] if i & 1 else lo[0],
                  hi[1] if i & 2 else lo[1],
                  hi[2] if i & 4 else lo[2]]
    faces = [
        (0, 2, 3, 1),  # -Z
        (4, 5, 7, 6),  # +Z
        (0, 1, 5, 4),  # -Y
        (2, 6, 7, 3),  # +Y
        (0, 4, 6, 2),  # -X
        (1, 3, 7, 5),  # +X
    ]
    return pts, [4] * 6, [i for f in faces for i in f]


def frame_box_mesh(origin: Sequence[float], ex: Sequence[float], ey: Sequence[float],
                   ez: Sequence[float]) -> MeshData:
    """Parallelepiped origin + [0, 1] * ex + [0, 1] * ey + [0, 1] * ez as 6 quads (8 points).

    It uses `box_mesh`'s point order and faces, so it is wound outward when
    (ex, ey, ez) is right-handed (det > 0), as for the axis-aligned box.
    """
    o = np.asarray(origin, dtype=np.float64)
    e = [np.asarray(v, dtype=np.float64) for v in (ex, ey, ez)]
    if float(np.dot(np.cross(e[0], e[1]), e[2])) <= 0.0:
        raise ValueError("frame_box_mesh: edges must be right-handed")
    pts = np.empty((8, 3), dtype=np.float64)
    for i in range(8):  # bit 0 -> ex, bit 1 -> ey, bit 2 -> ez
        pts[i] = o + (i & 1) * e[0] + ((i >> 1) & 1) * e[1] + ((i >> 2) & 1) * e[2]
    _, counts, idx = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    return pts, counts, idx


def bar_mesh(p0: Sequence[float], p1: Sequence[float], thickness: float) -> MeshData:
    """Thin closed box with a square thickness x thickness cross-section whose axis runs
    from p0 to p1 (its end faces lie in the planes through p0 and p1).  8 points, 6 quads,
    wound outward.  The cross-section is turned so that one side is horizontal (for a
    nearly vertical bar: perpendicular to X)."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    d = p1 - p0
    u = d / math.sqrt(float(np.dot(d, d)))
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    a = np.cross(u, ref)
    a /= math.sqrt(float(np.dot(a, a)))
    b = np.cross(u, a)  # a x b = u: (a, b, d) is right-handed
    t = float(thickness)
    return frame_box_mesh(p0 - 0.5 * t * (a + b), t * a, t * b, d)


def quad_mesh(corners: Sequence[Sequence[float]]) -> MeshData:
    """Single quad from 4 corners given in counter-clockwise order."""
    return np.asarray(corners, dtype=np.float64), [4], [0, 1, 2, 3]


def uv_sphere_y(radius: float, segments: int, stacks: int) -> MeshData:
    """Triangle UV sphere centred at the origin with its poles on the Y axis.

    The bottom pole is a vertex at (0, -radius, 0), so the sphere touches a
    ground plane y = -radius in exactly one point.
    """
    pts = [(0.0, radius, 0.0)]
    for k in range(1, stacks):
        phi = math.pi * k / stacks  # from +Y (0) to -Y (pi)
        y = radius * math.cos(phi)
        r = radius * math.sin(phi)
        for s in range(segments):
            th = 2.0 * math.pi * s / segments
            pts.append((r * math.cos(th), y, -r * math.sin(th)))
    pts.append((0.0, -radius, 0.0))
    top, bottom = 0, len(pts) - 1

    def ring(k: int, s: int) -> int:  # k in 1..stacks-1
        return 1 + (k - 1) * segments + (s % segments)

    idx: list[int] = []
    for s in range(segments):
        idx += [top, ring(1, s), ring(1, s + 1)]
    for k in range(1, stacks - 1):
        for s in range(segments):
            a, b = ring(k, s), ring(k, s + 1)
            c, d = ring(k + 1, s + 1), ring(k + 1, s)
            idx += [a, d, c, a, c, b]
    for s in range(segments):
        idx += [bottom, ring(stacks - 1, s + 1), ring(stacks - 1, s)]
    return np.asarray(pts, dtype=np.float64), [3] * (len(idx) // 3), idx


def prism_z(n: int, radius: float, z0: float, z1: float,
            center: Sequence[float] = (0.0, 0.0), phase: float = 0.0) -> MeshData:
    """Right prism with regular n-gon caps (n-gon faces kept as single faces)."""
    cx, cy = center
    th = [phase + 2.0 * math.pi * k / n for k in range(n)]
    bot = [(cx + radius * math.cos(t), cy + radius * math.sin(t), z0) for t in th]
    top = [(cx + radius * math.cos(t), cy + radius * math.sin(t), z1) for t in th]
    pts = np.asarray(bot + top, dtype=np.float64)
    counts: list[int] = []
    idx: list[int] = []
    counts.append(n)
    idx += list(range(n))[::-1]  # bottom cap, facing -Z
    counts.append(n)
    idx += [n + k for k in range(n)]  # top cap, facing +Z
    for k in range(n):
        k1 = (k + 1) % n
        counts.append(4)
        idx += [k, k1, n + k1, n + k]
    return pts, counts, idx


def torus_z(major: float, minor: float, nu: int, nv: int) -> MeshData:
    """Quad torus around the Z axis, centred at the origin."""
    pts = []
    for i in range(nu):
        u = 2.0 * math.pi * i / nu
        for j in range(nv):
            v = 2.0 * math.pi * j / nv
            rr = major + minor * math.cos(v)
            pts.append((rr * math.cos(u), rr * math.sin(u), minor * math.sin(v)))
    idx: list[int] = []
    for i in range(nu):
        for j in range(nv):
            a = i * nv + j
            b = ((i + 1) % nu) * nv + j
            c = ((i + 1) % nu) * nv + (j + 1) % nv
            d = i * nv + (j + 1) % nv
            idx += [a, b, c, d]
    return np.asarray(pts, dtype=np.float64), [4] * (nu * nv), idx


def translate_mesh(m: MeshData, t: Sequence[float]) -> MeshData:
    """The mesh moved by ``t``."""
    return m[0] + np.asarray(t, dtype=np.float64), m[1], m[2]


def merge_meshes(parts: Sequence[MeshData]) -> MeshData:
    """One mesh holding every part (indices offset, no points shared)."""
    pts, counts, idx, off = [], [], [], 0
    for p, c, i in parts:
        pts.append(p)
        counts += list(c)
        idx += [k + off for k in i]
        off += len(p)
    return np.concatenate(pts, axis=0), counts, idx


def weld(m: MeshData) -> MeshData:
    """Merge points with bit-identical float32 coordinates (deterministic)."""
    p32 = m[0].astype(np.float32)
    uniq, inverse = np.unique(p32, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    idx = [int(inverse[i]) for i in m[2]]
    return uniq.astype(np.float64), list(m[1]), idx


def triangle_count(counts: Sequence[int]) -> int:
    """Triangles of faces with these vertex counts (n - 2 each)."""
    return int(sum(c - 2 for c in counts))


def signed_volume(m: MeshData) -> float:
    """Signed volume enclosed by the faces (fan-triangulated): positive when wound outward."""
    p, counts, idx = m
    counts = np.asarray(counts)
    idx = np.asarray(idx)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vol = 0.0
    for c in np.unique(counts):
        st = starts[counts == c]
        for k in range(1, c - 1):
            a, b, d = p[idx[st]], p[idx[st + k]], p[idx[st + k + 1]]
            vol += float(np.einsum("ij,ij->i", a, np.cross(b, d)).sum())
    return vol / 6.0


def grid_quad_mesh(origin: Sequence[float], u: Sequence[float], v: Sequence[float],
                   nu: int, nv: int) -> MeshData:
    """Planar nu x nv grid of quads spanning origin + [0, 1] * u + [0, 1] * v.

    The quads are wound counter-clockwise seen from the side u x v points to.
    """
    o = np.asarray(origin, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    a = np.linspace(0.0, 1.0, nu + 1)
    b = np.linspace(0.0, 1.0, nv + 1)
    pts = o + a[None, :, None] * u + b[:, None, None] * v  # (nv+1, nu+1, 3)
    idx: list[int] = []
    for j in range(nv):
        for i in range(nu):
            p0 = j * (nu + 1) + i
            idx += [p0, p0 + 1, p0 + nu + 2, p0 + nu + 1]
    return pts.reshape(-1, 3), [4] * (nu * nv), idx


def grid_box_mesh(lo: Sequence[float], hi: Sequence[float], n: Sequence[int]) -> MeshData:
    """Axis-aligned closed box whose faces are grids of n[0] x n[1] x n[2] cells.

    All six faces take their coordinates from the same per-axis arrays, so the
    points along shared edges are bit-identical and `weld` joins them into one
    closed, outward-wound surface.
    """
    vals = [np.linspace(float(lo[k]), float(hi[k]), int(n[k]) + 1) for k in range(3)]
    parts: list[MeshData] = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3  # e_b x e_c = +e_a
        vb, vc = vals[b], vals[c]
        nb, nc = len(vb), len(vc)
        for side, val in ((-1, float(lo[a])), (1, float(hi[a]))):
            pts = np.empty((nc, nb, 3), dtype=np.float64)
            pts[:, :, a] = val
            pts[:, :, b] = vb[None, :]
            pts[:, :, c] = vc[:, None]
            idx: list[int] = []
            for j in range(nc - 1):
                for i in range(nb - 1):
                    p0 = j * nb + i
                    q = [p0, p0 + 1, p0 + nb + 1, p0 + nb]  # normal +e_a
                    idx += q if side > 0 else q[::-1]
            parts.append((pts.reshape(-1, 3), [4] * ((nb - 1) * (nc - 1)), idx))
    return weld(merge_meshes(parts))


def z_sphere(radius: float, segments: int, stacks: int) -> MeshData:
    """`uv_sphere_y` turned so its poles lie on the Z axis (bottom pole at z = -radius)."""
    p, counts, idx = uv_sphere_y(radius, segments, stacks)
    # rotation of +90 degrees about X: (x, y, z) -> (x, -z, y), keeps the winding outward
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1), counts, idx


def check_closed(m: MeshData, what: str) -> None:
    """Raise unless every directed edge appears once with its reverse once and the
    enclosed volume is positive (closed, consistently wound, normals out)."""
    _, counts, idx = m
    edges = set()
    o = 0
    for c in counts:
        f = idx[o:o + c]
        for k in range(c):
            e = (f[k], f[(k + 1) % c])
            if e in edges:
                raise RuntimeError("%s: directed edge %s used twice" % (what, e))
            edges.add(e)
        o += c
    if any((b, a) not in edges for a, b in edges):
        raise RuntimeError("%s: mesh is not closed" % what)
    if signed_volume(m) <= 0.0:
        raise RuntimeError("%s: mesh is wound inward" % what)


def face_normals(m: MeshData) -> np.ndarray:
    """Unit normal of every face (Newell's method), as (F, 3)."""
    p, counts, idx = m
    out = np.zeros((len(counts), 3), dtype=np.float64)
    o = 0
    for f, c in enumerate(counts):
        q = p[idx[o:o + c]]
        r = np.roll(q, -1, axis=0)
        n = np.array([np.sum((q[:, 1] - r[:, 1]) * (q[:, 2] + r[:, 2])),
                      np.sum((q[:, 2] - r[:, 2]) * (q[:, 0] + r[:, 0])),
                      np.sum((q[:, 0] - r[:, 0]) * (q[:, 1] + r[:, 1]))])
        out[f] = n / math.sqrt(float(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]))
        o += c
    return out


def flatten_below(m: MeshData, z0: float = 0.0) -> MeshData:
    """Clamp z >= z0: the parts pushed below the ground become flat soles on it."""
    p = m[0].copy()
    p[:, 2] = np.maximum(p[:, 2], z0)
    return p, m[1], m[2]


def rot_z(a: float) -> np.ndarray:
    """3 x 3 rotation by ``a`` radians about Z."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    """3 x 3 rotation by ``a`` radians about Y."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_x(a: float) -> np.ndarray:
    """3 x 3 rotation by ``a`` radians about X."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def place(m: MeshData, rot: np.ndarray, t: Sequence[float], scale: float = 1.0) -> MeshData:
    """The mesh scaled, rotated by ``rot`` and moved by ``t``."""
    return (m[0] * scale) @ rot.T + np.asarray(t, dtype=np.float64), m[1], m[2]


def zmin32(m: MeshData) -> float:
    """The lowest z of the points as written (float32)."""
    return float(np.asarray(m[0], dtype=np.float32)[:, 2].min())


def bounds32(m: MeshData) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of the points as written (float32)."""
    p = np.asarray(m[0], dtype=np.float32)
    return p.min(axis=0), p.max(axis=0)
