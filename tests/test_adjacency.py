"""Mesh adjacency (welding, edges) and silhouette edges against a brute force on the triangles."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from wsoft.scene.adjacency import build_adjacency, prim_adjacency, silhouettes, silhouettes_warp, upload_adjacency
from wsoft.scene.types import Material, Scene


def split_uv_sphere(seg: int = 24, stacks: int = 12, r: float = 1.0):
    """A UV sphere as a UV-mapped mesh stores it: a (seg+1) x (stacks+1) grid of points, the seam
    column and every pole point duplicated (split vertices); quads as two CCW (outward) triangles;
    the pole rows' degenerate triangles dropped."""
    th = np.linspace(0.0, 2 * math.pi, seg + 1)
    th[-1] = 0.0  # the seam column: exactly the same positions as column 0
    ph = np.linspace(0.0, math.pi, stacks + 1)
    P = np.stack([np.sin(ph)[:, None] * np.cos(th)[None, :], np.sin(ph)[:, None] * np.sin(th)[None, :],
                  np.cos(ph)[:, None] * np.ones_like(th)[None, :]], -1) * r
    P[0, :] = (0.0, 0.0, r)
    P[-1, :] = (0.0, 0.0, -r)
    idx = lambda i, j: i * (seg + 1) + j  # noqa: E731
    tris = []
    for i in range(stacks):
        for j in range(seg):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            if i > 0:
                tris.append((a, b, d))
            if i < stacks - 1:
                tris.append((b, c, d))
    return P.reshape(-1, 3).astype(np.float32), np.array(tris, np.int32)


def split_box(lo=(-1.0, -0.5, -0.7), hi=(1.2, 0.8, 0.3)):
    """A box with 4 points per face (24 points, every corner split three ways), outward CCW."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    corner = lambda i: np.where([(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1], hi, lo)  # noqa: E731
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    pts, tris = [], []
    for f in faces:
        base = len(pts)
        pts += [corner(i) for i in f]
        tris += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(pts, np.float32), np.array(tris, np.int32)


def scene_of(points, tris, prim_of=None) -> Scene:
    t = len(tris)
    return Scene(path="test", points=points, triangles=tris,
                 tri_prim=np.zeros(t, np.int32) if prim_of is None else prim_of, tri_material=np.zeros(t, np.int32),
                 tri_uv=np.zeros((t, 3, 2), np.float32), tri_double_sided=np.zeros(t, bool), prims=["/a", "/b"],
                 materials=[Material(path="(default)")])


def brute_silhouettes(points, tris, light, point: bool):
    """Every undirected edge of the triangles (by exact position), with the facing of each of its
    triangles tested directly: {frozenset of the two positions: oriented position pair}."""
    P = points.astype(np.float64)
    by_edge: dict = {}
    for t in tris:
        v = P[t]
        n = np.cross(v[1] - v[0], v[2] - v[0])
        if np.linalg.norm(n) == 0.0:
            continue
        front = (n @ (light - v[0]) if point else n @ light) > 0.0
        for k in range(3):
            a, b = tuple(v[k]), tuple(v[(k + 1) % 3])
            by_edge.setdefault(frozenset((a, b)), []).append((a, b, front))
    out = {}
    for key, hs in by_edge.items():
        if len(hs) == 2:
            (a, b, f0), (_, _, f1) = hs
            if f0 == f1:
                continue
        else:
            a, b, f0 = hs[0]
        out[key] = (a, b) if f0 else (b, a)
    return out


def as_position_pairs(adj, sign):
    e = adj.oriented(sign)
    P = adj.points.astype(np.float64)
    return {frozenset((tuple(P[a]), tuple(P[b]))): (tuple(P[a]), tuple(P[b])) for a, b in e}


LIGHTS = [((3.0, 0.5, 2.0), True), ((0.0, 0.0, 5.0), True), ((-0.3, 1.5, 0.1), True), ((0.2, 0.1, -4.0), True),
          ((1.0, 1.0, 1.0), False), ((0.0, -0.2, 1.0), False)]


@pytest.mark.parametrize("mesh", [split_uv_sphere, split_box])
def test_closed_meshes_weld_and_silhouettes_equal_brute_force(mesh, device):
    pts, tris = mesh()
    adj = build_adjacency(pts, tris)
    assert len(adj.points) < len(np.unique(tris))  # the split points were welded
    assert adj.closed and len(adj.open_edges) == 0 and not adj.nonmanifold.any()
    assert adj.edge_count * 2 == 3 * len(adj.faces)  # closed: every edge has two faces
    gpu = upload_adjacency(adj, device)
    for L, point in LIGHTS:
        kw = {"position": L} if point else {"direction": L}
        sign = silhouettes(adj, **kw)
        assert np.count_nonzero(sign) >= 4  # a silhouette loop really exists
        assert as_position_pairs(adj, sign) == brute_silhouettes(pts, tris, np.asarray(L), point)
        assert np.array_equal(silhouettes_warp(adj, gpu, **kw).numpy()[: adj.edge_count], sign)


def test_oriented_silhouette_has_the_occluder_on_its_negative_side():
    pts, tris = split_uv_sphere()
    adj = build_adjacency(pts, tris)
    L = np.array([3.0, 0.5, 2.0])
    sign = silhouettes(adj, position=L)
    e = adj.oriented(sign)
    P = adj.points.astype(np.float64)
    a, b = P[e[:, 0]], P[e[:, 1]]
    m = np.cross(a - L, b - L)
    # the sphere's centre (inside the occluder) lies on the negative side of every silhouette plane
    assert np.all(np.einsum("ij,ij->i", m, -L[None, :]) < 0.0)


def test_open_quad_all_four_edges_are_silhouettes():
    pts = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], np.float32)
    tris = np.array([(0, 1, 2), (0, 2, 3)], np.int32)
    adj = build_adjacency(pts, tris)
    assert adj.edge_count == 5 and len(adj.open_edges) == 4
    for L in [(0.3, 0.2, 2.0), (0.3, 0.2, -2.0)]:
        sign = silhouettes(adj, position=L)
        assert np.count_nonzero(sign) == 4 and sign[adj.edge_faces[:, 1] >= 0].tolist() == [0]
        assert as_position_pairs(adj, sign) == brute_silhouettes(pts, tris, np.asarray(L), True)


def test_degenerate_and_nonmanifold_triangles():
    pts = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (0, 0, 0), (0, -1, 0), (0, 0, 1)], np.float32)
    # a zero-area collinear triangle (0, 1, 3), a triangle with a repeated welded corner (0, 4, 2),
    # and three triangles on the edge 0-1 (non-manifold)
    tris = np.array([(0, 1, 2), (0, 1, 3), (0, 4, 2), (1, 0, 5), (0, 1, 6)], np.int32)
    adj = build_adjacency(pts, tris)
    assert len(adj.faces) == 4 and 2 not in adj.tris  # the repeated-corner triangle is left out
    assert adj.nonmanifold.sum() == 4  # edge 0-1 has 4 faces (collinear one included): 4 open records
    sign = silhouettes(adj, position=(0.2, 0.2, 3.0))
    assert np.all(sign[adj.nonmanifold] != 0)
    assert np.all(np.isfinite(adj.face_n))


def test_scene_cache_per_prim_and_changed():
    p1, t1 = split_box()
    p2, t2 = split_uv_sphere(8, 4)
    pts = np.concatenate([p1, p2])
    tris = np.concatenate([t1, t2 + len(p1)])
    prim = np.r_[np.zeros(len(t1), np.int32), np.ones(len(t2), np.int32)]
    s = scene_of(pts, tris, prim)
    a0, a1 = prim_adjacency(s, 0), prim_adjacency(s, 1)
    assert a0.closed and a1.closed and np.array_equal(np.sort(a1.tris), np.arange(len(t1), len(tris)))
    assert prim_adjacency(s, 0) is a0
    s.changed()
    assert prim_adjacency(s, 0) is not a0


def timing(n_seg: int = 1000, n_stacks: int = 500):
    """Times of the silhouette test for a ~1M-edge sphere: NumPy and the Warp kernel (CPU)."""
    import time

    pts, tris = split_uv_sphere(n_seg, n_stacks)
    t0 = time.perf_counter()
    adj = build_adjacency(pts, tris)
    t1 = time.perf_counter()
    gpu = upload_adjacency(adj, "cpu")
    silhouettes_warp(adj, gpu, position=(3.0, 0.5, 2.0))  # compile / load
    out = {"edges": adj.edge_count, "build_s": t1 - t0}
    for name, f in (("numpy", lambda: silhouettes(adj, position=(3.0, 0.5, 2.0))),
                    ("warp", lambda: (silhouettes_warp(adj, gpu, position=(3.0, 0.5, 2.0)), wp.synchronize()))):
        ts = []
        for _ in range(5):
            t = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t)
        out[name + "_s"] = min(ts)
    return out


if __name__ == "__main__":
    print(timing())


def test_potential_silhouettes_hold_every_silhouette_from_the_bound():
    """Every edge that is a silhouette from some point of a light's ball is a potential one, and a
    small far light leaves most of a sphere's edges out (the filter does something)."""
    from wsoft.scene.adjacency import build_adjacency, potential_silhouettes, silhouettes

    rng = np.random.default_rng(3)
    u, v = np.meshgrid(np.linspace(0, np.pi, 24), np.linspace(0, 2 * np.pi, 48, endpoint=False), indexing="ij")
    pts = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], -1).reshape(-1, 3)
    tri = []
    for i in range(23):
        for j in range(48):
            a, b, c, d = i * 48 + j, i * 48 + (j + 1) % 48, (i + 1) * 48 + j, (i + 1) * 48 + (j + 1) % 48
            tri += [[a, c, b], [b, c, d]]
    adj = build_adjacency(pts.astype(np.float32), np.array(tri))
    centre, radius = np.array([0.3, -0.2, 6.0]), 0.5
    pot = potential_silhouettes(adj, centre, radius, False)
    for _ in range(200):
        q = rng.normal(size=3)
        q = centre + radius * rng.random() ** (1 / 3) * q / np.linalg.norm(q)
        assert not np.any((silhouettes(adj, position=q) != 0) & ~pot)
    assert pot.mean() < 0.3
