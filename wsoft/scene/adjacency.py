"""Mesh adjacency and silhouette edges, for the object-based techniques (penumbra wedges, depth
complexity sampling) that extrude primitives from the silhouette edges of opaque meshes.

Built once per mesh prim (:func:`prim_adjacency`, cached on the :class:`~wsoft.scene.types.Scene`
and forgotten by ``Scene.changed()``), in vectorized NumPy:

* **Welding.** USD meshes split a vertex wherever a primvar (``st``, normals) is face-varying:
  at a UV seam the same position appears as two points, and the mesh looks open there. The
  points of a prim are welded when their float32 positions are exactly equal (``-0.0`` counts as
  ``0.0``); no tolerance, so two surfaces that merely touch stay apart. Triangles whose welded
  corners repeat a vertex (zero area by construction) are left out of the adjacency.
* **Edges.** Each undirected welded edge is one record with its one or two triangles. An edge
  with one triangle is *open* (always a silhouette). An edge shared by more than two triangles
  (*non-manifold*) is split into one open record per triangle: every one of them is always a
  silhouette (conservative: a technique extrudes each triangle's side separately, as if the
  triangles did not touch).
* **Silhouettes** (:func:`silhouettes`, :func:`silhouettes_warp`) seen from a point (a local
  light's centre) or along a direction (a distant light): an edge whose two triangles face
  opposite ways from the light — for two triangles that wind the edge the same way (an
  inconsistently wound pair) the geometric rule is used instead: both triangles' far corners lie
  on the same side of the plane through the light and the edge — or an open edge.

Silhouette orientation: the result for edge ``e`` is ``+1`` (silhouette, oriented ``edges[e]``,
``a -> b``), ``-1`` (silhouette, oriented ``b -> a``) or ``0``. The orientation is the one the
edge has in its triangle that faces the light (its corners counter-clockwise seen from the light;
for an open edge whose triangle faces away, the reverse of that triangle's). Then the occluding
triangle lies on the *negative* side of the plane through the light and the oriented edge, whose
normal is ``(a - L) x (b - L)`` for a light at ``L`` and ``(b - a) x d`` for a light in direction
``d`` (from the scene toward the light): a wedge or volume side built from ``a -> b`` has its
inside on the side of that normal's negative half-space — the shadow region of the occluder.

A triangle *faces* the light when ``n . (L - v0) > 0`` (point) or ``n . d > 0`` (direction),
``n = (v1 - v0) x (v2 - v0)``; a zero-area triangle faces nowhere (both tests are 0).

Speed (2 CPU cores, a 1.5M-edge sphere, ``python tests/test_adjacency.py``): building the adjacency
about 2 s (once per mesh); the silhouette test 20 ms in NumPy (float64), 17 ms as the chunked Warp
kernel :func:`silhouettes_warp` — about equal on the CPU; a GPU technique uses the kernel.

Instanced geometry (``Scene.instances``) is not covered: adjacency is of the triangle soup.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked


@dataclass
class Adjacency:
    """Welded connectivity of one mesh.

    ``points``: [W, 3] float32 welded positions; ``faces``: [F, 3] int32 welded corners of the
    triangles kept (``tris[f]`` is the scene triangle of face ``f``); ``edges``: [E, 2] int32, each
    edge oriented as in its first face ``edge_faces[e, 0]``; ``edge_faces``: [E, 2] int32 local
    face indices, ``-1`` in column 1 for an open (or split non-manifold) edge; ``consistent``:
    [E] bool, the second face winds the edge ``b -> a`` (a consistently wound pair);
    ``nonmanifold``: [E] bool, the record comes from an edge with more than two faces;
    ``face_n``: [F, 3] float32 unit face normals (zero for a degenerate face), ``face_d``: [F] float32 ``n . v0``."""

    points: np.ndarray
    faces: np.ndarray
    tris: np.ndarray
    vertex_of_point: np.ndarray  # [P] int32: welded vertex of each input point (-1: unused)
    edges: np.ndarray
    edge_faces: np.ndarray
    consistent: np.ndarray
    nonmanifold: np.ndarray
    face_n: np.ndarray
    face_d: np.ndarray

    @property
    def edge_count(self) -> int:
        return int(self.edges.shape[0])

    @property
    def open_edges(self) -> np.ndarray:
        """Indices of the edges with one face (open or split non-manifold)."""
        return np.flatnonzero(self.edge_faces[:, 1] < 0)

    @property
    def closed(self) -> bool:
        """Is every edge shared by exactly two consistently wound faces?"""
        return bool(self.edge_count) and bool(np.all(self.edge_faces[:, 1] >= 0) and np.all(self.consistent))

    def oriented(self, sign: np.ndarray) -> np.ndarray:
        """The silhouette edges of a :func:`silhouettes` result as oriented welded vertex pairs [S, 2]."""
        sel = np.flatnonzero(sign != 0)
        e = self.edges[sel]
        return np.where((sign[sel] > 0)[:, None], e, e[:, ::-1]).astype(np.int32)


def weld_points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Welded positions [W, 3] float32 and each point's welded index [P] int32: points whose float32
    coordinates are exactly equal (``-0.0 == 0.0``) become one. Deterministic (sorted order)."""
    p = np.ascontiguousarray(np.asarray(points, np.float32) + np.float32(0.0))  # -0.0 -> +0.0
    if len(p) == 0:
        return np.zeros((0, 3), np.float32), np.zeros(0, np.int32)
    keys = p.view(np.dtype((np.void, 12))).reshape(-1)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return p[first], inverse.reshape(-1).astype(np.int32)


def triangle_parts(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Per triangle of ``triangles`` ([T, 3] indices into ``points``), the connected part of the
    mesh it belongs to (triangles sharing a corner, corners welded by position,
    :func:`weld_points`): [T] int32 labels from 0."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    T = len(triangles)
    if T == 0:
        return np.zeros(0, np.int32)
    _, corner = weld_points(np.asarray(points)[triangles.reshape(-1)])  # a welded index per corner
    n = T + int(corner.max()) + 1
    rows = np.repeat(np.arange(T, dtype=np.int64), 3)
    graph = coo_matrix((np.ones(3 * T, np.int8), (rows, T + corner.astype(np.int64))), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return np.unique(labels[:T], return_inverse=True)[1].astype(np.int32)


def build_adjacency(points: np.ndarray, triangles: np.ndarray, tris: np.ndarray | None = None) -> Adjacency:
    """Adjacency of the triangles ``triangles`` ([T, 3] indices into ``points``); ``tris`` names
    them in the caller's numbering (default ``arange(T)``)."""
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    tris = np.arange(len(triangles), dtype=np.int32) if tris is None else np.asarray(tris, np.int32)
    used = np.unique(triangles) if len(triangles) else np.zeros(0, np.int64)
    wpts, winv = weld_points(np.asarray(points)[used])
    vmap = np.full(len(points), -1, np.int32)
    vmap[used] = winv
    faces = vmap[triangles] if len(triangles) else np.zeros((0, 3), np.int32)
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces, tris = faces[keep].astype(np.int32), tris[keep]
    F = len(faces)

    # half-edges: face f, corner k -> (faces[f, k], faces[f, k+1])
    a = faces.reshape(-1).astype(np.int64)
    b = faces[:, [1, 2, 0]].reshape(-1).astype(np.int64)
    hf = np.repeat(np.arange(F, dtype=np.int32), 3)
    W = max(len(wpts), 1)
    key = np.minimum(a, b) * W + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]) if len(ks) else np.zeros(0, np.int64)
    counts = np.diff(np.r_[starts, len(ks)])

    two = starts[counts == 2]
    h0, h1 = order[two], order[two + 1]
    per = np.repeat(counts, counts)  # the size of its edge's group, per sorted half-edge
    lone = np.flatnonzero(per != 2)
    single = order[lone]  # open edges and the split non-manifold ones
    nm_single = per[lone] > 2

    first = np.r_[h0, single]
    edges = np.stack([a[first], b[first]], axis=1).astype(np.int32)
    edge_faces = np.stack([hf[first], np.r_[hf[h1], np.full(len(single), -1, np.int32)]], axis=1).astype(np.int32)
    consistent = np.r_[a[h1] == b[h0], np.zeros(len(single), bool)]
    nonmanifold = np.r_[np.zeros(len(two), bool), nm_single]

    p = wpts.astype(np.float64)
    if F:
        v0, v1, v2 = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
        n = np.cross(v1 - v0, v2 - v0)
        # unit normals (zero for a degenerate face): the facing tests read only signs, and a huge
        # triangle's unnormalised normal (coordinates near 1e30 give 1e60) has no float32
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
        f32 = float(np.finfo(np.float32).max)
        d = np.clip(np.einsum("ij,ij->i", n, v0), -f32, f32)
    else:
        n, d = np.zeros((0, 3)), np.zeros(0)
    return Adjacency(points=wpts, faces=faces, tris=tris, vertex_of_point=vmap, edges=edges, edge_faces=edge_faces,
                     consistent=consistent, nonmanifold=nonmanifold, face_n=n.astype(np.float32), face_d=d.astype(np.float32))


def prim_adjacency(scene, prim: int) -> Adjacency:
    """The adjacency of prim ``prim``'s triangles in ``scene`` (``tris`` are scene triangle indices),
    built once and kept in ``scene.__dict__['_adjacency']`` (``Scene.changed()`` forgets it)."""
    cache = scene.__dict__.setdefault("_adjacency", {})
    if prim not in cache:
        sel = np.flatnonzero(scene.tri_prim == prim).astype(np.int32)
        cache[prim] = build_adjacency(scene.points, scene.triangles[sel], sel)
    return cache[prim]


def scene_adjacency(scene, tri_mask: np.ndarray | None = None) -> list[Adjacency]:
    """The adjacency of every prim that has triangles (those ``tri_mask`` selects, if given)."""
    tp = scene.tri_prim if tri_mask is None else scene.tri_prim[np.asarray(tri_mask, bool)]
    return [prim_adjacency(scene, int(p)) for p in np.unique(tp)]


def potential_silhouettes(adj: Adjacency, centre, radius: float, distant: bool) -> np.ndarray:
    """[E] bool: the edges that are silhouettes from some point of a light's bound — a ball
    (``centre``, ``radius``) or, ``distant``, a cone of directions (unit ``centre`` toward the
    light, ``radius`` the sine of its half angle): open and split non-manifold edges, and edges
    whose faces are not both surely facing the same way (consistently wound pairs) or surely
    facing opposite ways (inconsistent pairs) over the whole bound. A face surely faces the bound
    when its plane's height over the centre exceeds the radius (``n . d > sin a`` for a cone).
    Faces with non-finite normals (huge coordinates) count as unsure."""
    c = np.asarray(centre, np.float64)
    n = adj.face_n.astype(np.float64)
    ln = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        h = n @ c - (0.0 if distant else adj.face_d.astype(np.float64))
        front = h > radius * ln
        back = h < -radius * ln
    ef = adj.edge_faces
    has1 = ef[:, 1] >= 0
    f0, f1 = ef[:, 0], np.maximum(ef[:, 1], 0)
    same = np.where(adj.consistent, (front[f0] & front[f1]) | (back[f0] & back[f1]), (front[f0] & back[f1]) | (back[f0] & front[f1]))
    return ~has1 | ~same


def silhouette_candidates(scene, tri_mask: np.ndarray, centre, radius: float, distant: bool) -> tuple[np.ndarray, np.ndarray]:
    """The potential silhouette edges (:func:`potential_silhouettes`) of the triangles ``tri_mask``
    ([T] bool) selects, prim by prim: corners [E, 4, 3] float32 (the edge's ``a``, ``b``, the far
    corner of its face 0, of its face 1 — face 0's again for an open edge) and the number of faces
    [E] int32 (1: open or split non-manifold, 2). A prim whose triangles are only partly selected
    (cutout subsets, prims a light's link leaves out) gets the adjacency of the selected ones."""
    tri_mask = np.asarray(tri_mask, bool)
    out_pts, out_nf = [], []
    for prim in np.unique(scene.tri_prim[tri_mask]):
        sel = np.flatnonzero(scene.tri_prim == prim)
        keep = tri_mask[sel]
        adj = prim_adjacency(scene, int(prim)) if keep.all() else build_adjacency(scene.points, scene.triangles[sel[keep]], sel[keep].astype(np.int32))
        if adj.edge_count == 0:
            continue
        e = np.flatnonzero(potential_silhouettes(adj, centre, radius, distant))
        if not len(e):
            continue
        a, b = adj.edges[e, 0], adj.edges[e, 1]
        has1 = adj.edge_faces[e, 1] >= 0

        def far_corner(f):
            fc = adj.faces[f]
            return np.where((fc[:, 0] != a) & (fc[:, 0] != b), fc[:, 0], np.where((fc[:, 1] != a) & (fc[:, 1] != b), fc[:, 1], fc[:, 2]))

        o0 = far_corner(adj.edge_faces[e, 0])
        o1 = np.where(has1, far_corner(np.maximum(adj.edge_faces[e, 1], 0)), o0)
        P = adj.points
        out_pts.append(np.stack([P[a], P[b], P[o0], P[o1]], axis=1))
        out_nf.append(np.where(has1, 2, 1).astype(np.int32))
    if not out_pts:
        return np.zeros((0, 4, 3), np.float32), np.zeros(0, np.int32)
    return np.concatenate(out_pts).astype(np.float32), np.concatenate(out_nf)


def _light4(position=None, direction=None) -> np.ndarray:
    """(x, y, z, w): w = 1 a point, w = 0 a direction toward the light."""
    if (position is None) == (direction is None):
        raise ValueError("give exactly one of position (a local light's centre) or direction (toward a distant light)")
    if position is not None:
        return np.r_[np.asarray(position, np.float64), 1.0]
    return np.r_[np.asarray(direction, np.float64), 0.0]


def facing(adj: Adjacency, position=None, direction=None) -> np.ndarray:
    """[F] bool: does each face face the light (see the module docstring)?"""
    L = _light4(position, direction)
    s = adj.face_n.astype(np.float64) @ L[:3] - L[3] * adj.face_d.astype(np.float64)
    return s > 0.0


def silhouettes(adj: Adjacency, position=None, direction=None) -> np.ndarray:
    """[E] int8 silhouette signs (+1 / -1 / 0, module docstring) from a point light at ``position``
    or a distant light in ``direction`` (from the scene toward the light). NumPy."""
    front = facing(adj, position, direction)
    ef = adj.edge_faces
    f0 = front[ef[:, 0]]
    has1 = ef[:, 1] >= 0
    f1 = front[np.maximum(ef[:, 1], 0)]
    sil = ~has1 | np.where(adj.consistent, f0 != f1, f0 == f1)
    return np.where(sil, np.where(f0, 1, -1), 0).astype(np.int8)


@wp.kernel
def classify_silhouettes(
    offset: int,
    face_n: wp.array[wp.vec3],
    face_d: wp.array[float],
    edge_faces: wp.array[wp.vec2i],
    consistent: wp.array[wp.int8],
    light: wp.vec4,
    # outputs
    sign: wp.array[wp.int8],
):
    """Per edge: +1 / -1 silhouette (oriented as stored / reversed), 0 not (module docstring).
    ``light``: xyz a point (w = 1) or a direction toward the light (w = 0)."""
    e = wp.tid() + offset
    L = wp.vec3(light[0], light[1], light[2])
    f0 = edge_faces[e][0]
    f1 = edge_faces[e][1]
    front0 = wp.dot(face_n[f0], L) - light[3] * face_d[f0] > 0.0
    sil = True
    if f1 >= 0:
        front1 = wp.dot(face_n[f1], L) - light[3] * face_d[f1] > 0.0
        if consistent[e] != wp.int8(0):
            sil = front0 != front1
        else:
            sil = front0 == front1
    out = wp.int8(0)
    if sil:
        out = wp.int8(-1)
        if front0:
            out = wp.int8(1)
    sign[e] = out


@dataclass
class AdjacencyGPU:
    """An :class:`Adjacency`'s arrays on one device, for :func:`silhouettes_warp`."""

    face_n: wp.array
    face_d: wp.array
    edge_faces: wp.array
    consistent: wp.array
    device: str


def upload_adjacency(adj: Adjacency, device: str) -> AdjacencyGPU:
    def nonempty(a, shape):
        return a if len(a) else np.zeros(shape, a.dtype)

    return AdjacencyGPU(
        face_n=wp.array(nonempty(adj.face_n, (1, 3)), dtype=wp.vec3, device=device),
        face_d=wp.array(nonempty(adj.face_d, (1,)), dtype=float, device=device),
        edge_faces=wp.array(nonempty(adj.edge_faces, (1, 2)), dtype=wp.vec2i, device=device),
        consistent=wp.array(nonempty(adj.consistent.astype(np.int8), (1,)), dtype=wp.int8, device=device),
        device=device,
    )


def silhouettes_warp(adj: Adjacency, gpu: AdjacencyGPU, position=None, direction=None, out: wp.array | None = None) -> wp.array:
    """:func:`silhouettes` as a Warp launch (chunked across CPU threads): [E] int8 on ``gpu.device``.
    Light coordinates are float32 on the device (NumPy's version computes in float64: the two can
    differ for an edge whose faces are within float32 rounding of grazing)."""
    E = adj.edge_count
    if out is None:
        out = wp.zeros(max(E, 1), dtype=wp.int8, device=gpu.device)
    L = _light4(position, direction)
    launch_chunked(classify_silhouettes, E, inputs=[gpu.face_n, gpu.face_d, gpu.edge_faces, gpu.consistent, wp.vec4(*L)],
                   outputs=[out], device=gpu.device, min_chunk=65536, per_thread=1)
    return out
