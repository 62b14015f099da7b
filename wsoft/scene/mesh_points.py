"""What a bake (:mod:`wsoft.baking`) needs of a mesh: its faces' corners, a world normal per corner,
whether one value per vertex is enough, and ``st`` per corner.

Topology, authored normals and ``st`` are read from the USD prim at the bake's time code; the world
positions are the loaded :class:`~wsoft.scene.types.Scene`'s own (``Scene.prim_points``: the same
float32 points the kernels see).

**Normals.** A mesh's authored normals (``primvars:normals``, else the ``normals`` attribute) are
used as authored, through the inverse transpose of the world transform: ``vertex``, ``varying``
and ``constant`` ones give one normal per vertex; ``faceVarying`` ones one per face corner (one
per vertex where the corners of every vertex agree within :data:`AUTHORED_AGREE_DEG`); ``uniform``
ones replace the faces' normals below. Without them each face's normal is its geometric one
(Newell's, area-weighted, turned to the front by ``orientation`` and a mirroring transform, as
the loader winds its triangles). The *crease rule*: the normal of a face corner is the
area-weighted mean of the normals of the faces around its vertex that lie within
``crease_angle`` (default :data:`CREASE_ANGLE`) of its own face's normal. A vertex whose faces
all lie within ``crease_angle`` of each other is *smooth*: every corner gets the same normal, the
area-weighted mean of all its faces. A mesh whose vertices are all smooth is baked with
``vertex`` interpolation (one value per point), else with ``faceVarying`` (one value per face
corner, so a cube's corner has three values, one per face).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wsoft.scene.polygons import triangulate

CREASE_ANGLE = 30.0
"""Degrees: faces around a vertex closer than this share its normal (a smooth vertex); farther ones
make a crease (faceVarying values)."""

AUTHORED_AGREE_DEG = 0.1
"""Degrees: authored faceVarying normals of one vertex that agree this closely are one normal."""


@dataclass
class MeshSurface:
    """A mesh prim's faces for a bake, in world space. ``C`` face corners (``faceVertexIndices``
    order), ``V`` points, ``F`` faces."""

    path: str
    points: np.ndarray
    """[V, 3] float64 world positions (the scene's float32 points)."""
    corner_vertex: np.ndarray
    """[C] int64: the point of each corner (``faceVertexIndices``)."""
    corner_face: np.ndarray
    """[C] int64: the face of each corner."""
    corner_valid: np.ndarray
    """[C] bool: the corner's face has three or more corners and a normal (others get no value: 1)."""
    corner_normal: np.ndarray
    """[C, 3] float64 unit world normal of each corner (zero where not valid)."""
    corner_crease: np.ndarray
    """[C] bool: the corner's normal differs from another corner's of the same vertex."""
    vertex_normal: np.ndarray
    """[V, 3] float64 unit normal per point (zero for points no valid corner uses)."""
    interpolation: str
    """``vertex`` (every vertex smooth) or ``faceVarying``."""
    normals: str
    """Where the normals came from: ``authored <interpolation>`` or ``geometric``."""
    face_centroid: np.ndarray
    """[F, 3] float64 mean of each face's corners."""
    tri_corners: np.ndarray
    """[T, 3] int64: corners of the triangles of the valid faces that are not holes (face order;
    :func:`~wsoft.scene.polygons.triangulate`, as the loader triangulates them)."""
    tri_face: np.ndarray
    """[T] int64: the face of each triangle."""
    st: np.ndarray | None
    """[C, 2] float32 ``st`` per corner, or None without (or with an unusable) ``st``."""
    warnings: list[str]


def _pv_per_corner(values: np.ndarray, interp: str, corner_vertex: np.ndarray, corner_face: np.ndarray) -> np.ndarray | None:
    """A primvar's (flattened) values at each face corner; None when too few for its interpolation."""
    try:
        if interp == "faceVarying":
            return values[np.arange(len(corner_vertex))]
        if interp in ("vertex", "varying"):
            return values[corner_vertex]
        if interp == "uniform":
            return values[corner_face]
        return np.broadcast_to(values[0], (len(corner_vertex), values.shape[1])).copy()
    except IndexError:
        return None


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit rows of ``v``, their lengths); zero rows stay zero."""
    n = np.linalg.norm(v, axis=-1)
    return np.where(n[..., None] > 0, v / np.where(n > 0, n, 1.0)[..., None], 0.0), n


def read_mesh_surface(prim, time_code, world_points: np.ndarray, world: np.ndarray, crease_angle: float = CREASE_ANGLE) -> MeshSurface | None:
    """The :class:`MeshSurface` of the ``UsdGeom.Mesh`` ``prim`` at ``time_code`` (a ``Usd.TimeCode``).

    ``world_points``: its points in world space, in its own order (``Scene.prim_points``);
    ``world``: its 4x4 local-to-world matrix (column vectors). None for a mesh without faces."""
    from pxr import UsdGeom

    path = str(prim.GetPath())
    mesh = UsdGeom.Mesh(prim)
    counts = mesh.GetFaceVertexCountsAttr().Get(time_code)
    indices = mesh.GetFaceVertexIndicesAttr().Get(time_code)
    if counts is None or indices is None or len(counts) == 0:
        return None
    counts = np.asarray(counts, np.int64)
    cv = np.asarray(indices, np.int64)
    P = np.asarray(world_points, np.float64)
    F, C = len(counts), len(cv)
    warns: list[str] = []
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    cf = np.repeat(np.arange(F), counts)
    face_ok = counts >= 3
    # Newell's normal of each face (twice its area vector), about the face's centroid
    nxt = np.arange(C) + 1
    last = starts + counts - 1
    nxt[last[counts > 0]] = starts[counts > 0]
    centroid = np.zeros((F, 3))
    np.add.at(centroid, cf, P[cv])
    centroid /= np.maximum(counts, 1)[:, None]
    a, b = P[cv] - centroid[cf], P[cv[nxt]] - centroid[cf]
    fn = np.zeros((F, 3))
    np.add.at(fn, cf, np.cross(a, b))
    M3 = np.asarray(world, np.float64)[:3, :3]
    flip = (-1.0 if mesh.GetOrientationAttr().Get(time_code) == UsdGeom.Tokens.leftHanded else 1.0) * (-1.0 if np.linalg.det(M3) < 0 else 1.0)
    face_n, face_w = _unit(fn * flip)
    face_w = 0.5 * face_w  # area

    # authored normals
    authored, interp = None, None
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
    if pv and pv.HasValue():
        vals, interp = pv.ComputeFlattened(time_code), str(pv.GetInterpolation())
    else:
        attr = mesh.GetNormalsAttr()
        vals = attr.Get(time_code) if attr and attr.HasValue() else None
        interp = str(mesh.GetNormalsInterpolation())
    if vals is not None and len(vals):
        n_local = np.asarray(vals, np.float64).reshape(-1, 3)
        inv_t = np.linalg.inv(M3).T if abs(np.linalg.det(M3)) > 0 else M3
        n_world, _ = _unit(n_local @ inv_t.T)
        if interp == "uniform":
            if len(n_world) < F:
                warns.append(f"{path}: normals has {len(n_world)} values, too few for uniform interpolation; geometric normals used")
            else:
                face_n = np.where(np.linalg.norm(n_world[:F], axis=1)[:, None] > 0, n_world[:F], face_n)
                interp = "uniform"
                authored = "uniform"
        else:
            per_corner = _pv_per_corner(n_world, interp, cv, cf)
            if per_corner is None or (interp in ("vertex", "varying") and len(n_world) < len(P)):
                warns.append(f"{path}: normals has {len(n_world)} values, too few for {interp} interpolation; geometric normals used")
            else:
                authored = per_corner

    valid = face_ok[cf] & (face_w[cf] > 0)
    cos_crease = math.cos(math.radians(crease_angle))
    order = np.argsort(cv, kind="stable")
    order = order[valid[order]]  # the valid corners, grouped by vertex
    sv = cv[order]
    # groups of the corners of one vertex (sorted by vertex)
    first = np.concatenate([[True], sv[1:] != sv[:-1]]) if len(sv) else np.zeros(0, bool)
    gstart_of = np.maximum.accumulate(np.where(first, np.arange(len(sv)), 0)) if len(sv) else np.zeros(0, np.int64)
    gsize = np.bincount(np.cumsum(first) - 1) if len(sv) else np.zeros(0, np.int64)
    gsize_of = gsize[np.cumsum(first) - 1] if len(sv) else np.zeros(0, np.int64)
    vertex_normal = np.zeros((len(P), 3))
    if isinstance(authored, np.ndarray):
        cn = np.where(np.linalg.norm(authored, axis=1)[:, None] > 0, authored, face_n[cf])
        corner_n = np.where(valid[:, None], cn, 0.0)
        agree = math.cos(math.radians(AUTHORED_AGREE_DEG))
        if interp in ("vertex", "varying", "constant"):
            crease = np.zeros(C, bool)
        else:
            crease = np.zeros(C, bool)
            ref = corner_n[order][gstart_of]  # the first corner's normal of each vertex
            crease[order] = np.einsum("ij,ij->i", corner_n[order], ref) < agree
            bad_v = np.unique(sv[crease[order]])
            crease[valid & np.isin(cv, bad_v)] = True
        np.add.at(vertex_normal, cv[valid], corner_n[valid])
        vertex_normal, _ = _unit(vertex_normal)
        normals = f"authored {interp}"
    else:
        # the crease rule over the corners of each vertex (pairs within crease_angle of each other)
        fo = cf[order]
        nf = face_n[fo]
        wf = (face_w[fo])[:, None] * nf
        acc = np.zeros((len(sv), 3))
        cnt = np.zeros(len(sv), np.int64)
        kmax = int(gsize.max()) if len(gsize) else 0
        pos = np.arange(len(sv))
        for j in range(kmax):
            act = pos[gsize_of > j]
            other = gstart_of[act] + j
            close = np.einsum("ij,ij->i", nf[act], nf[other]) >= cos_crease
            acc[act[close]] += wf[other[close]]
            cnt[act[close]] += 1
        corner_n = np.zeros((C, 3))
        cn_sorted, ln = _unit(acc)
        cn_sorted = np.where(ln[:, None] > 0, cn_sorted, nf)
        corner_n[order] = cn_sorted
        crease = np.zeros(C, bool)
        crease[order] = cnt < gsize_of
        bad_v = np.unique(sv[cnt < gsize_of])
        crease[valid & np.isin(cv, bad_v)] = True
        np.add.at(vertex_normal, sv, wf)
        vertex_normal, _ = _unit(vertex_normal)
        normals = "authored uniform" if authored == "uniform" else "geometric"
    # a vertex whose mean normal vanishes (faces facing away from each other): its corners' own
    vn_zero = np.linalg.norm(vertex_normal, axis=1) == 0
    used = np.zeros(len(P), bool)
    used[cv[valid]] = True
    if np.any(vn_zero & used):
        crease[valid & vn_zero[cv]] = True
    interpolation = "faceVarying" if crease[valid].any() else "vertex"

    # triangles of the valid faces that are not holes (for texels), as the loader triangulates them
    fvalid = face_ok & (face_w > 0)
    holes = mesh.GetHoleIndicesAttr().Get(time_code)
    if holes is not None and len(holes):
        h = np.asarray(holes, np.int64)
        fvalid[h[(h >= 0) & (h < F)]] = False
    tri = triangulate(P, counts, cv, keep=fvalid)
    tri_corners, tri_face = tri.corners, tri.faces

    st = None
    spv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    if spv and spv.HasValue():
        svals = spv.ComputeFlattened(time_code)
        if svals is not None and len(svals):
            st = _pv_per_corner(np.asarray(svals, np.float32).reshape(-1, 2), str(spv.GetInterpolation()), cv, cf)
            if st is None:
                warns.append(f"{path}: primvars:st has {len(svals)} values, too few for {spv.GetInterpolation()} interpolation; no texture")
    return MeshSurface(path=path, points=P, corner_vertex=cv, corner_face=cf, corner_valid=valid, corner_normal=corner_n,
                       corner_crease=crease & valid, vertex_normal=vertex_normal, interpolation=interpolation, normals=normals,
                       face_centroid=centroid, tri_corners=tri_corners, tri_face=tri_face, st=st, warnings=warns)
