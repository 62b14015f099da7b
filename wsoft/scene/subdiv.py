"""Uniform refinement of subdivision surfaces (``UsdGeom.Mesh`` with a ``subdivisionScheme``), in numpy.

:func:`refine` subdivides a mesh's control cage ``level`` times and returns a :class:`Refinement`:
the refined points, the refined faces (each remembering the cage face it comes from) and the means
to refine any primvar the same way. The rules are OpenSubdiv's (USD's reference), with its
``uniform`` creasing:

- ``catmullClark``: every face of ``n`` corners splits into ``n`` quads (face point, edge points,
  vertex point); after one step every face is a quad. Smooth rules: face point = centroid; edge
  point = (v0 + v1 + f0 + f1) / 4; vertex point = (Q + 2R + (n - 3) v) / n (``Q`` the mean of the
  face points, ``R`` of the edge midpoints around the vertex, ``n`` its edges).
- ``loop``: triangles only (another face is a ``ValueError``); each splits into 4. Edge point =
  3/8 (v0 + v1) + 1/8 (a + b) (``a``, ``b`` the opposite corners); vertex point =
  (1 - n beta) v + beta (sum of its neighbours), beta = (5/8 - (3/8 + cos(2 pi / n) / 4)^2) / n.
- ``bilinear``: the Catmull–Clark split with linear points (centroid, midpoint, the vertex itself).

**Sharp features** (both smooth schemes). An edge of sharpness ``s > 0`` has the crease edge
point (the midpoint), blended with the smooth one by ``s`` when ``s < 1``; a vertex with exactly
two sharp edges has the crease rule (a + 6 v + b) / 8 (a cubic B-spline along the crease), one with
more than two sharp edges or a sharpness of its own (``cornerIndices``) stays where it is. Each
step lowers every sharpness by 1 (``s >= 10``, :data:`INFINITE`, never: an infinitely sharp crease
or corner), and a vertex whose rule changes between a step and the next one is blended by
OpenSubdiv's fractional weight (the semi-sharp rule). Boundary edges (one face) and non-manifold
edges (more than two) are infinitely sharp, so the boundary is the cubic B-spline curve of the
boundary vertices. ``interpolateBoundary`` (:class:`Tags`): ``edgeAndCorner`` (USD's default) also
makes a boundary vertex with one face an infinitely sharp corner; ``edgeOnly`` does not (the
boundary curve runs smoothly through it); ``none`` refines like ``edgeOnly`` but draws no face that
touches a boundary vertex (:attr:`Refinement.boundary_faces`; the limit surface is not defined
there).

**Primvars.** ``vertex`` ones are refined by the scheme's rules (:meth:`Refinement.vertex`),
``varying`` ones linearly (:meth:`Refinement.varying`), ``uniform`` ones are read at the parent
face (:attr:`Refinement.parent`). ``faceVarying`` ones (texture coordinates) are refined bilinearly
inside each face (:meth:`Refinement.face_varying`): a refined corner's value is its parent face's
corner value, the mean of two of them (edge points) or of all of them (face point). That is
exactly ``faceVaryingLinearInterpolation = all``; USD's other modes smooth the values in a face's
interior, which this rule does not.

Faces of fewer than three corners take no part in the refinement. Holes (faces that are not
drawn) are refined as every face: they shape their neighbours, and the caller leaves their refined
faces out (:attr:`Refinement.parent`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SCHEMES = ("catmullClark", "loop", "bilinear")
"""The ``subdivisionScheme`` values that refine (``none`` is a polygon mesh)."""

MAX_LEVEL = 4
"""The highest ``subdiv_level``: each level multiplies a mesh's faces by 4."""

MAX_FACES = 1 << 24
"""The most faces one mesh may be refined into (a larger one is an error asking for a lower level)."""

INFINITE = 10.0
"""A sharpness at least this large is infinite: it never decreases (OpenSubdiv's ``SHARPNESS_INFINITE``)."""

BOUNDARY_MODES = ("edgeAndCorner", "edgeOnly", "none")
"""``interpolateBoundary`` values (USD's default: ``edgeAndCorner``)."""

_SMOOTH, _CREASE, _CORNER = 0, 1, 2


def check_level(level) -> int:
    """``level`` as an int in ``0 .. MAX_LEVEL``; anything else is a ``ValueError`` saying so."""
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= int(level) <= MAX_LEVEL:
        raise ValueError(f"subdiv_level {level!r} is not an integer in 0..{MAX_LEVEL} (0: the control cage; each level has 4x the faces)")
    return int(level)


def refined_face_count(counts: np.ndarray, scheme: str, level: int) -> int:
    """How many faces ``level`` steps make of faces with ``counts`` corners (faces of fewer than 3
    corners dropped)."""
    counts = np.asarray(counts, np.int64)
    live = counts[counts >= 3]
    if level == 0:
        return int(len(live))
    if scheme == "loop":
        return int(len(live)) * 4 ** level
    return int(live.sum()) * 4 ** (level - 1)


@dataclass
class Tags:
    """A mesh's sharp features (cage vertex indices) and its ``interpolateBoundary``."""

    boundary: str = "edgeAndCorner"
    crease_edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    """[K, 2] int64: edges (vertex pairs, either order) given a sharpness."""
    crease_sharpness: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    """[K] float64, per crease edge (>= :data:`INFINITE`: infinitely sharp)."""
    corners: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """[M] int64: vertices given a sharpness."""
    corner_sharpness: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    """[M] float64."""


def crease_edges(indices, lengths, sharpness) -> tuple[np.ndarray, np.ndarray]:
    """USD's ``creaseIndices`` / ``creaseLengths`` / ``creaseSharpnesses`` as edges and a sharpness
    per edge: crease ``i`` is a chain of ``lengths[i]`` vertices (``lengths[i] - 1`` edges); its
    sharpness is ``sharpness[i]`` (one per crease) or one per edge (as many values as edges). A
    ``ValueError`` when the counts disagree."""
    idx = np.asarray(indices if indices is not None else [], np.int64)
    ln = np.asarray(lengths if lengths is not None else [], np.int64)
    sh = np.asarray(sharpness if sharpness is not None else [], np.float64)
    if np.any(ln < 0):
        raise ValueError("creaseLengths has a negative length")
    if int(ln.sum()) != len(idx):
        raise ValueError(f"creaseLengths sum to {int(ln.sum())} but creaseIndices has {len(idx)} entries")
    edges_per = np.maximum(ln - 1, 0)
    n_edges = int(edges_per.sum())
    if len(sh) == len(ln):
        per_edge = np.repeat(sh, edges_per)
    elif len(sh) == n_edges:
        per_edge = sh
    else:
        raise ValueError(f"creaseSharpnesses has {len(sh)} values for {len(ln)} creases of {n_edges} edges (one per crease or per edge)")
    starts = np.concatenate([[0], np.cumsum(ln)[:-1]]) if len(ln) else np.zeros(0, np.int64)
    crease = np.repeat(np.arange(len(ln)), edges_per)
    k = np.arange(n_edges) - np.repeat(np.cumsum(edges_per) - edges_per, edges_per)
    first = starts[crease] + k
    return np.stack([idx[first], idx[first + 1]], axis=1).reshape(-1, 2), per_edge


class _Step:
    """One refinement step: the parent level's topology and the rules of each of its vertices."""

    def __init__(self, counts: np.ndarray, indices: np.ndarray, nverts: int, scheme: str, boundary: str,
                 edge_keys: np.ndarray, edge_sharp: np.ndarray, vertex_sharp: np.ndarray):
        self.scheme, self.V = scheme, int(nverts)
        C, F = len(indices), len(counts)
        self.F, self.counts = F, counts
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if F else np.zeros(0, np.int64)
        fc = np.repeat(np.arange(F), counts)
        k = np.arange(C) - starts[fc]
        last = k == counts[fc] - 1
        nxt = np.where(last, starts[fc], np.arange(C) + 1)
        prv = np.where(k == 0, starts[fc] + counts[fc] - 1, np.arange(C) - 1)
        cv = np.asarray(indices, np.int64)
        a, b = cv, cv[nxt]
        keys = np.minimum(a, b) * self.V + np.maximum(a, b)
        uniq, ce = np.unique(keys, return_inverse=True)
        ce = ce.ravel()
        E = len(uniq)
        ev = np.stack([uniq // self.V, uniq % self.V], axis=1)
        self.E, self.fc, self.cv, self.ce, self.nxt, self.prv, self.ev = E, fc, cv, ce, nxt, prv, ev
        self.edge_faces = np.bincount(ce, minlength=E)
        self.vertex_faces = np.bincount(cv, minlength=self.V)
        self.vertex_edges = np.bincount(ev.ravel(), minlength=self.V)

        # sharpness: carried creases, then boundary and non-manifold edges infinitely sharp
        s = np.zeros(E, np.float64)
        if len(edge_keys):
            pos = np.clip(np.searchsorted(uniq, edge_keys), 0, max(E - 1, 0))
            found = (uniq[pos] == edge_keys) if E else np.zeros(len(edge_keys), bool)
            np.maximum.at(s, pos[found], edge_sharp[found])
            self.unmatched = int((~found).sum())
        else:
            self.unmatched = 0
        s[self.edge_faces != 2] = INFINITE
        vs = np.asarray(vertex_sharp, np.float64).copy()
        if boundary == "edgeAndCorner":
            vs[self.vertex_faces == 1] = INFINITE
        self.edge_sharp, self.vertex_sharp = s, vs
        child_s, child_vs = _decrement(s), _decrement(vs)
        self.child_edge_sharp, self.child_vertex_sharp = child_s, child_vs

        if scheme == "bilinear":
            return
        # edge points: the crease (midpoint) weight
        self.edge_w = np.minimum(s, 1.0)
        # vertex rules before and after the step, and the semi-sharp blend between them
        p_sharp, c_sharp = s > 0, child_s > 0
        p_count = np.bincount(ev[p_sharp].ravel(), minlength=self.V)
        c_count = np.bincount(ev[c_sharp].ravel(), minlength=self.V)
        self.p_rule = _rule(vs, p_count, self.vertex_edges)
        self.c_rule = _rule(child_vs, c_count, self.vertex_edges)
        trans_e = p_sharp & ~c_sharp
        t_sum = np.bincount(ev[trans_e].ravel(), weights=np.repeat(s[trans_e], 2), minlength=self.V).astype(np.float64)
        t_cnt = np.bincount(ev[trans_e].ravel(), minlength=self.V).astype(np.float64)
        tv = (vs > 0) & ~(child_vs > 0)
        t_sum += np.where(tv, vs, 0.0)
        t_cnt += tv
        self.blend = np.where(t_cnt > 0, np.minimum(t_sum / np.maximum(t_cnt, 1), 1.0), 0.0)
        self.p_sharp, self.c_sharp = p_sharp, c_sharp
        if scheme == "loop":
            n = np.maximum(self.vertex_edges, 1).astype(np.float64)
            self.beta = (5.0 / 8.0 - (3.0 / 8.0 + 0.25 * np.cos(2.0 * np.pi / n)) ** 2) / n

    # -- child topology

    def child_topology(self) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
        """The refined faces (counts, indices), the refined vertex count and each refined face's
        parent face (in this level)."""
        V, E = self.V, self.E
        if self.scheme == "loop":
            F = self.F
            corner_tris = np.stack([self.cv, V + self.ce, V + self.ce[self.prv]], axis=1).reshape(F, 3, 3)
            center = (V + self.ce).reshape(F, 1, 3)
            idx = np.concatenate([corner_tris, center], axis=1).reshape(-1)
            return np.full(4 * F, 3, np.int64), idx, V + E, np.repeat(np.arange(F), 4)
        idx = np.stack([self.cv, V + self.ce, V + E + self.fc, V + self.ce[self.prv]], axis=1).reshape(-1)
        return np.full(len(self.cv), 4, np.int64), idx, V + E + self.F, self.fc

    def child_creases(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The refined level's crease edges (as keys into its vertices), their sharpness, and the
        refined vertices' own sharpness."""
        V, E = self.V, self.E
        nv = V + E + (self.F if self.scheme != "loop" else 0)
        keep = np.flatnonzero(self.child_edge_sharp > 0)
        mid = V + keep
        a = np.concatenate([self.ev[keep, 0], self.ev[keep, 1]])
        b = np.concatenate([mid, mid])
        keys = np.minimum(a, b) * nv + np.maximum(a, b)
        sharp = np.concatenate([self.child_edge_sharp[keep]] * 2)
        vs = np.zeros(nv, np.float64)
        vs[:V] = self.child_vertex_sharp
        return keys, sharp, vs

    # -- data

    def _face_mean(self, d: np.ndarray, per_corner: bool = False) -> np.ndarray:
        """Each face's mean of per-vertex values ``d`` (or, ``per_corner``, of its corners' values)."""
        return _sum_by(self.fc, d if per_corner else d[self.cv], self.F) / np.maximum(self.counts, 1)[:, None]

    def linear(self, d: np.ndarray) -> np.ndarray:
        """Refined values, every point linear (bilinear split; varying primvars)."""
        mid = 0.5 * (d[self.ev[:, 0]] + d[self.ev[:, 1]])
        parts = [d, mid] if self.scheme == "loop" else [d, mid, self._face_mean(d)]
        return np.concatenate(parts, axis=0)

    def apply(self, d: np.ndarray) -> np.ndarray:
        """Refined values by the scheme's rules (points, vertex primvars): ``d`` [V, k] float64."""
        if self.scheme == "bilinear":
            return self.linear(d)
        V, ev = self.V, self.ev
        d0, d1 = d[ev[:, 0]], d[ev[:, 1]]
        mid = 0.5 * (d0 + d1)
        nbr = _sum_by(ev.ravel(), d[ev[:, ::-1].ravel()], V)  # the sum of each vertex's edge neighbours
        if self.scheme == "loop":
            opp = _sum_by(self.ce, d[self.cv[self.prv]], self.E)
            smooth_e = 0.375 * (d0 + d1) + 0.125 * opp
            smooth_v = (1.0 - self.vertex_edges * self.beta)[:, None] * d + self.beta[:, None] * nbr
            fp = None
        else:
            fp = self._face_mean(d)
            fsum_e = _sum_by(self.ce, fp[self.fc], self.E)
            smooth_e = 0.25 * (d0 + d1 + fsum_e)
            n = np.maximum(self.vertex_edges, 1).astype(np.float64)[:, None]
            q = _sum_by(self.cv, fp[self.fc], V) / np.maximum(self.vertex_faces, 1)[:, None]
            r = 0.5 * (n * d + nbr) / n
            smooth_v = (q + 2.0 * r + (n - 3.0) * d) / n
        w = self.edge_w[:, None]
        ep = w * mid + (1.0 - w) * smooth_e
        vp = self._vertex_points(d, smooth_v)
        parts = [vp, ep] if fp is None else [vp, ep, fp]
        return np.concatenate(parts, axis=0)

    def _vertex_points(self, d: np.ndarray, smooth_v: np.ndarray) -> np.ndarray:
        ev, V = self.ev, self.V

        def crease(sharp: np.ndarray) -> np.ndarray:
            e = ev[sharp]
            s = _sum_by(e.ravel(), d[e[:, ::-1].ravel()], V)
            return (s + 6.0 * d) / 8.0

        def at(rule: np.ndarray, sharp: np.ndarray) -> np.ndarray:
            out = np.where((rule == _SMOOTH)[:, None], smooth_v, d)
            cr = rule == _CREASE
            if cr.any():
                out = np.where(cr[:, None], crease(sharp), out)
            return out

        vp = at(self.p_rule, self.p_sharp)
        differ = self.p_rule != self.c_rule
        if differ.any():
            w = self.blend[:, None]
            vc = at(self.c_rule, self.c_sharp)
            vp = np.where(differ[:, None], w * vp + (1.0 - w) * vc, vp)
        return vp

    def face_varying(self, d: np.ndarray) -> np.ndarray:
        """Refined per-corner values (``d`` [C, k] in this level's corner order), bilinear in each face."""
        m = 0.5 * (d + d[self.nxt])
        if self.scheme == "loop":
            F = self.F
            corner = np.stack([d, m, m[self.prv]], axis=1).reshape(F, 3, 3, -1)
            center = m.reshape(F, 1, 3, -1)
            return np.concatenate([corner, center], axis=1).reshape(-1, d.shape[1])
        fm = self._face_mean(d, per_corner=True)
        return np.stack([d, m, fm[self.fc], m[self.prv]], axis=1).reshape(-1, d.shape[1])


def _decrement(s: np.ndarray) -> np.ndarray:
    return np.where(s >= INFINITE, s, np.maximum(s - 1.0, 0.0))


def _rule(vertex_sharp: np.ndarray, sharp_edges: np.ndarray, edges: np.ndarray) -> np.ndarray:
    rule = np.where(sharp_edges == 2, _CREASE, np.where(sharp_edges > 2, _CORNER, _SMOOTH))
    return np.where((vertex_sharp > 0) | (edges == 0), _CORNER, rule)


def _sum_by(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Rows of ``values`` [N, k] summed into ``n`` bins by ``index`` [N]."""
    k = values.shape[1]
    out = np.empty((n, k), np.float64)
    for j in range(k):
        out[:, j] = np.bincount(index, weights=values[:, j], minlength=n)
    return out


@dataclass
class Refinement:
    """A mesh refined ``level`` times (:func:`refine`)."""

    points: np.ndarray
    """[V', 3] float64 refined points; the first ``V`` are the cage's own vertices, moved."""
    counts: np.ndarray
    """[F'] int64 corners of each refined face (4 for Catmull–Clark and bilinear, 3 for Loop; the cage's faces at level 0)."""
    indices: np.ndarray
    """[C'] int64 refined faces' corners, wound as their parent faces."""
    parent: np.ndarray
    """[F'] int64: the cage face each refined face comes from."""
    boundary_faces: np.ndarray
    """[F] bool per cage face: it touches a boundary vertex (``interpolateBoundary = none`` leaves it out when refined)."""
    unmatched_creases: int
    """Crease edges of the tags that are not edges of the cage (ignored)."""
    scheme: str
    level: int
    cage_points: int = 0
    """``V``: the cage's point count."""
    cage_corners: np.ndarray = field(repr=False, default=None)
    """[C] bool: the cage corners that take part (those of faces of 3 or more corners)."""
    steps: list = field(repr=False, default_factory=list)

    def vertex(self, values) -> np.ndarray:
        """Per-vertex values [V, k] of the cage refined by the scheme's rules: [V', k] float64."""
        d = _as_2d(values)
        for st in self.steps:
            d = st.apply(d)
        return d

    def varying(self, values) -> np.ndarray:
        """Per-vertex values [V, k] refined linearly: [V', k] float64."""
        d = _as_2d(values)
        for st in self.steps:
            d = st.linear(d)
        return d

    def face_varying(self, values) -> np.ndarray:
        """Per-corner values [C, k] of the cage (``faceVertexIndices`` order) refined bilinearly in
        each face: [C', k] float64, in the refined corners' order."""
        d = _as_2d(values)[self.cage_corners]
        for st in self.steps:
            d = st.face_varying(d)
        return d


def _as_2d(values) -> np.ndarray:
    d = np.asarray(values, np.float64)
    return d[:, None] if d.ndim == 1 else d


def refine(points, counts, indices, scheme: str, level: int, tags: Tags | None = None) -> Refinement:
    """The mesh (``points`` [V, 3], ``counts`` [F], ``indices`` [C]) refined ``level`` times by
    ``scheme`` (:data:`SCHEMES`) with the sharp features and boundary mode ``tags``; see the
    module's documentation. A ``ValueError`` for an unknown scheme or boundary mode, a ``loop``
    mesh with a face that is not a triangle, or a refined mesh of more than :data:`MAX_FACES` faces."""
    level = check_level(level)
    if scheme not in SCHEMES:
        raise ValueError(f"subdivisionScheme {scheme!r} is not one of {', '.join(SCHEMES)}")
    tags = tags if tags is not None else Tags()
    if tags.boundary not in BOUNDARY_MODES:
        raise ValueError(f"interpolateBoundary {tags.boundary!r} is not one of {', '.join(BOUNDARY_MODES)}")
    p = np.asarray(points, np.float64).reshape(-1, 3)
    counts = np.asarray(counts, np.int64)
    idx = np.asarray(indices, np.int64)
    V = len(p)
    live = counts >= 3
    corner_live = np.repeat(live, counts)
    face_id = np.flatnonzero(live)
    c_counts, c_idx = counts[live], idx[corner_live]
    if scheme == "loop" and np.any(c_counts != 3):
        bad = int(face_id[np.argmax(c_counts != 3)])
        raise ValueError(f"subdivisionScheme loop needs triangles; face {bad} has {int(counts[bad])} corners "
                         "(triangulate the mesh, or author catmullClark)")
    total = refined_face_count(counts, scheme, level)
    if total > MAX_FACES:
        raise ValueError(f"subdiv_level {level} would refine its {len(face_id):,} faces into {total:,} (more than {MAX_FACES:,}); "
                         "use a lower level")
    ek = np.zeros(0, np.int64)
    es = np.zeros(0, np.float64)
    if len(tags.crease_edges):
        ce = np.asarray(tags.crease_edges, np.int64).reshape(-1, 2)
        ek = np.minimum(ce[:, 0], ce[:, 1]) * V + np.maximum(ce[:, 0], ce[:, 1])
        es = np.asarray(tags.crease_sharpness, np.float64)
    vs = np.zeros(V, np.float64)
    if len(tags.corners):
        np.maximum.at(vs, np.asarray(tags.corners, np.int64), np.asarray(tags.corner_sharpness, np.float64))
    # faces that touch a boundary vertex (an edge with one face) of the cage
    boundary_faces = np.zeros(len(counts), bool)
    steps: list[_Step] = []
    unmatched = 0
    cur_counts, cur_idx, nv, parent = c_counts, c_idx, V, face_id
    bmode = "edgeOnly" if tags.boundary == "none" else tags.boundary
    for i in range(level):
        st = _Step(cur_counts, cur_idx, nv, scheme, bmode, ek, es, vs)
        if i == 0:
            unmatched = st.unmatched
            on_boundary = np.zeros(nv, bool)
            on_boundary[st.ev[st.edge_faces == 1].ravel()] = True
            boundary_faces[face_id] = np.bincount(st.fc, weights=on_boundary[st.cv].astype(np.float64), minlength=st.F) > 0
        ek, es, vs = st.child_creases()
        cur_counts, cur_idx, nv, par = st.child_topology()
        parent = parent[par]
        p = st.apply(p)
        steps.append(st)
    return Refinement(points=p, counts=cur_counts, indices=cur_idx, parent=parent, boundary_faces=boundary_faces,
                      unmatched_creases=unmatched, scheme=scheme, level=level, cage_points=V, cage_corners=corner_live, steps=steps)


def limit_points_catmull_clark(points, counts, indices) -> np.ndarray:
    """The limit position of each vertex of an all-quad, closed Catmull–Clark mesh with no sharp
    feature: (n^2 v + 4 sum(e_j) + sum(f_j)) / (n (n + 5)), ``e_j`` its edge neighbours and ``f_j``
    the corners across its quads, ``n`` its valence (for tests and checks)."""
    p = np.asarray(points, np.float64)
    counts = np.asarray(counts, np.int64)
    if np.any(counts != 4):
        raise ValueError("the limit mask needs quads")
    q = np.asarray(indices, np.int64).reshape(-1, 4)
    out_e = np.zeros_like(p)
    out_f = np.zeros_like(p)
    n = np.zeros(len(p))
    for k in range(4):
        v, e, f = q[:, k], q[:, (k + 1) % 4], q[:, (k + 2) % 4]
        np.add.at(out_e, v, p[e])  # each edge is seen from two quads: halved below
        np.add.at(out_e, v, p[q[:, (k + 3) % 4]])
        np.add.at(out_f, v, p[f])
        np.add.at(n, v, 1.0)
    out_e *= 0.5
    n2 = n[:, None]
    return (n2 * n2 * p + 4.0 * out_e + out_f) / (n2 * (n2 + 5.0))


def limit_points_loop(points, indices) -> np.ndarray:
    """The limit position of each vertex of a closed Loop mesh (triangles ``indices`` [T*3]) with no
    sharp feature: (1 - n chi) v + chi sum(neighbours), chi = 1 / (3 / (8 beta) + n), beta Loop's
    weight of valence ``n`` (for tests and checks)."""
    p = np.asarray(points, np.float64)
    t = np.asarray(indices, np.int64).reshape(-1, 3)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    n = np.bincount(e.ravel(), minlength=len(p)).astype(np.float64)
    s = _sum_by(e.ravel(), p[e[:, ::-1].ravel()], len(p))
    beta = (5.0 / 8.0 - (3.0 / 8.0 + 0.25 * np.cos(2.0 * np.pi / n)) ** 2) / n
    chi = 1.0 / (3.0 / (8.0 * beta) + n)
    return (1.0 - n * chi)[:, None] * p + chi[:, None] * s
