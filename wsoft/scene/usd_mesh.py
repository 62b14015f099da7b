"""USD meshes with their materials and alpha textures -> :class:`~wsoft.scene.soup.MeshPart`.

:class:`MeshReader` reads a ``UsdGeom.Mesh``, or one of UsdGeom's shapes tessellated into one
(:mod:`wsoft.scene.shapes`), at the context's time code (:mod:`wsoft.scene.usd_context`):
a subdivision surface as its control cage, or refined ``subdiv_level`` times
(:mod:`wsoft.scene.subdiv`, :meth:`MeshReader.refinement`); its faces triangulated (:mod:`wsoft.scene.polygons`; the faces of ``holeIndices`` left out), its
points placed in the world, per triangle the material bound to the mesh or its ``GeomSubset``
faces, and per corner ``primvars:wsoft:bakedLight`` and the texture coordinates the triangle's
material samples its opacity texture at (the primvar its network reads, through its
``UsdTransform2d`` nodes, :meth:`MeshReader.texture_coords`). Materials (``UsdPreviewSurface``:
diffuse colour, opacity, opacityThreshold, an opacity texture network,
:mod:`wsoft.scene.usd_texture`, or a prim's ``displayColor`` without one) and textures are read once
each and kept in :attr:`MeshReader.materials` and :attr:`MeshReader.textures`.
:func:`closed_orientation` tells a closed surface (whose far faces the light view may skip).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wsoft.scene.polygons import Triangles, triangulate
from wsoft.scene.shapes import ShapeMesh, tessellate
from wsoft.scene.soup import MeshPart
from wsoft.scene.subdiv import BOUNDARY_MODES, MAX_LEVEL, SCHEMES, Refinement, Tags, crease_edges, refine
from wsoft.scene.types import Material, Texture
from wsoft.scene.usd_context import StageContext, pxr
from wsoft.scene.usd_skel import SkelReader
from wsoft.scene.usd_texture import OpacityNetwork


class MeshReader:
    """Meshes of one stage, and the materials and textures they use (index 0: the default material).

    ``subdiv_level``: how many times subdivision surfaces (``subdivisionScheme`` catmullClark, loop
    or bilinear; USD's fallback, when unauthored, is catmullClark) are refined; 0 reads their
    control cage. :meth:`subdivision_note` says which were read how."""

    def __init__(self, ctx: StageContext, subdiv_level: int = 0):
        self.ctx = ctx
        self.subdiv_level = subdiv_level
        self.subdivision: dict[str, tuple[str, bool, int, int]] = {}  # mesh path -> (scheme, authored?, cage faces, refined faces)
        self.materials: list[Material] = [Material(path="(default)")]
        self.material_index: dict[str, int] = {"": 0}
        self.network = OpacityNetwork(ctx)
        self.textures: list[Texture] = self.network.textures
        self.tile_index: dict[tuple[int, int], int] = {}  # (UDIM material, tile) -> the tile's material
        self.prototype_triangles: dict[str, tuple[Refinement | None, Triangles]] = {}  # a PointInstancer prototype's mesh path -> (refinement, triangles)
        self.prototype_shapes: dict[str, ShapeMesh | None] = {}  # a PointInstancer prototype's shape path -> its tessellation
        self.skel: SkelReader | None = None  # the stage's skinned meshes, read at the first mesh that may be one

    def read(self, prim) -> MeshPart | None:
        """A ``UsdGeom.Mesh`` (:meth:`read_mesh`) or one of UsdGeom's shapes (:meth:`read_shape`)."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        return self.read_mesh(prim) if prim.IsA(UsdGeom.Mesh) else self.read_shape(prim)

    def read_shape(self, prim) -> MeshPart | None:
        """One of UsdGeom's shapes (``Cube``, ``Sphere``, ``Cylinder``, ``Cone``, ``Capsule``, their
        ``_1`` forms, ``Plane``) tessellated in its local space (:func:`~wsoft.scene.shapes.tessellate`)
        and read as a mesh of those points and faces is (:meth:`place`): its ``orientation``,
        ``doubleSided`` (a plane's falls back to true), material or ``displayColor``, world transform;
        a dynamic caster when an attribute that shapes it is time-sampled. Its primvars are read only
        where constant (a shape has no authored faces or points to vary over). None (with a warning)
        for a shape with no area."""
        key = str(prim.GetPath()) if self.ctx.world_override is not None else None
        if key is not None and key in self.prototype_shapes:
            shape = self.prototype_shapes[key]
        else:
            shape = tessellate(self.ctx, prim)
            if key is not None:
                self.prototype_shapes[key] = shape
        if shape is None:
            return None
        return self.place(prim, shape.points, shape.counts, shape.indices, None, shape.attrs)

    def read_mesh(self, prim) -> MeshPart | None:
        """The mesh ``prim`` triangulated (:func:`~wsoft.scene.polygons.triangulate`: a fan from each
        face's first corner, concave faces ear-clipped; the faces of ``holeIndices`` left out;
        ``orientation`` respected, the winding flipped under a mirroring transform) in the world (or
        the frame of the context's ``world_override``), zero-area triangles dropped; None (with a
        warning) when nothing is left. Faces that cross themselves, non-planar concave faces and
        out-of-range hole indices are warned once per mesh. A subdivision surface with
        ``subdiv_level > 0`` is refined first (:meth:`refinement`): its refined faces are
        triangulated, each triangle keeps its cage face (``MeshPart.faces``: GeomSubset materials,
        uniform primvars) and primvars are refined with it (:meth:`read_primvar`)."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        mesh = UsdGeom.Mesh(prim)
        points = self.ctx.points(prim)  # USD's: extrapolated by velocities where authored
        counts = self.ctx.get(mesh.GetFaceVertexCountsAttr())
        indices = self.ctx.get(mesh.GetFaceVertexIndicesAttr())
        if points is None or counts is None or indices is None or len(points) == 0 or len(counts) == 0:
            self.ctx.warn(prim, "mesh has no points or faces; ignored")
            return None
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        counts = np.asarray(counts, dtype=np.int64)
        idx = np.asarray(indices, dtype=np.int64)
        if not np.all(np.isfinite(p)):
            bad = int(np.argwhere(~np.isfinite(p).all(axis=1))[0, 0])
            raise self.ctx.err(prim, f"points[{bad}] is not finite (NaN or inf)")
        if np.any(counts < 0):
            bad = int(np.argmax(counts < 0))
            raise self.ctx.err(prim, f"faceVertexCounts[{bad}] = {int(counts[bad])} is negative")
        if counts.sum() != len(idx):
            raise self.ctx.err(prim, f"faceVertexCounts sum to {int(counts.sum())} but faceVertexIndices has {len(idx)} entries")
        if len(idx) and (idx.min() < 0 or idx.max() >= len(p)):
            bad = int(np.argmax((idx < 0) | (idx >= len(p))))
            raise self.ctx.err(prim, f"faceVertexIndices[{bad}] = {int(idx[bad])} is out of range for {len(p)} points")
        if np.any(counts < 3):
            self.ctx.warn(prim, f"{int(np.sum(counts < 3))} faces with fewer than 3 vertices ignored")
        if SkelReader.may_be_skinned(prim):
            if self.ctx.world_override is not None:
                self.ctx.warn(prim, "a skinned mesh in a PointInstancer's prototype is drawn in its bind pose (UsdSkel poses it "
                              "only where it is bound in the stage itself)")
            else:
                self.skel = self.skel or SkelReader(self.ctx)
                posed = self.skel.pose(prim, p)
                if posed is not None:
                    return self.place(prim, posed.points, counts, idx, mesh, (mesh.GetPointsAttr(),), posed.world, posed.dynamic)
        return self.place(prim, p, counts, idx, mesh, (mesh.GetPointsAttr(),))

    def place(self, prim, p, counts, idx, mesh, shaping, world: np.ndarray | None = None, posed_dynamic: bool = False) -> MeshPart | None:
        """The gprim ``prim`` whose polygons are the points ``p`` (local space, float64), face counts
        and face indices given (checked), as a :class:`MeshPart`: triangulated (a ``UsdGeom.Mesh``
        ``mesh`` with its ``holeIndices``; None: a shape's convex faces), wound by its
        ``orientation`` and flipped under a mirroring transform, in the world, zero-area triangles
        dropped, with its materials, texture coordinates, sidedness, closedness and baked light;
        dynamic when one of the ``shaping`` attributes is time-sampled (or its transform is)."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        gprim = UsdGeom.Gprim(prim)
        # a prototype a PointInstancer places many times is refined, triangulated (and warned about) once
        key = str(prim.GetPath()) if self.ctx.world_override is not None else None
        cached = self.prototype_triangles.get(key) if key is not None else None
        if cached is None:
            ref = self.refinement(prim, mesh, p, counts, idx) if mesh is not None else None
            if ref is None:
                tri = self.triangulate(prim, mesh, p, counts, idx) if mesh is not None else triangulate(p, counts, idx)
            else:
                tri = self.triangulate(prim, mesh, ref.points, ref.counts, ref.indices, ref)
            cached = (ref, tri)
            if key is not None:
                self.prototype_triangles[key] = cached
        ref, tri = cached
        corners, face_of_tri = tri.corners, tri.faces
        if ref is not None:  # the refined mesh's points and corners; faces stay the cage's
            p, idx = ref.points, ref.indices
        orient = self.ctx.get(gprim.GetOrientationAttr(), UsdGeom.Tokens.rightHanded)
        if orient == UsdGeom.Tokens.leftHanded:
            corners = corners[:, [0, 2, 1]]
        tris = idx[corners]

        # world transform
        M = self.ctx.world(prim) if world is None else world  # a skinned mesh: its skeleton's (``world``)
        if not np.all(np.isfinite(M)):
            raise self.ctx.err(prim, "world transform is not finite (NaN or inf in its xformOps or an ancestor's)")
        with np.errstate(over="ignore", invalid="ignore"):
            pw = p @ M[:3, :3].T + M[:3, 3]
        pw32 = pw.astype(np.float32)  # what the kernels see
        if not np.all(np.isfinite(pw32)):
            bad = int(np.argwhere(~np.isfinite(pw32).all(axis=1))[0, 0])
            raise self.ctx.err(prim, f"points[{bad}] is not finite in float32 once transformed to world space ({p[bad].tolist()})")
        if np.linalg.det(M[:3, :3]) < 0:  # mirroring transform flips the winding
            corners = corners[:, [0, 2, 1]]
            tris = tris[:, [0, 2, 1]]

        # zero-area triangles (repeated or collinear corners in float32) cannot block a ray: dropped
        q = pw32.astype(np.float64)[tris]
        area2 = np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
        keep = area2 > 0.0
        if not keep.all():
            self.ctx.warn(prim, f"{int((~keep).sum())} zero-area triangles ignored")
            if not keep.any():
                return None
            tris, corners, face_of_tri = tris[keep], corners[keep], face_of_tri[keep]
        mat = self.bind_materials(prim, mesh, len(counts), face_of_tri)
        uv, mat = self.texture_coords(prim, corners, face_of_tri, tris, mat, shape=mesh is None, ref=ref)
        ds = bool(self.ctx.get(gprim.GetDoubleSidedAttr(), False))  # UsdGeom's uniform doubleSided (the eye view's back-face culling)
        stray = prim.GetAttribute("primvars:doubleSided")
        if stray and stray.HasAuthoredValue():
            self.ctx.warn(prim, "primvars:doubleSided is not a UsdGeom property; ignored (the mesh's doubleSided attribute "
                          f"is read: {str(ds).lower()})")
        baked = self.read_primvar(prim, corners, face_of_tri, tris, "wsoft:bakedLight", 3, shape=mesh is None, ref=ref)
        return MeshPart(points=pw, triangles=tris.astype(np.int32), material=mat, uv=uv, double_sided=ds, closed=closed_orientation(pw, tris),
                        dynamic=posed_dynamic or self.ctx.is_dynamic(prim, shaping), baked=baked, faces=face_of_tri)

    def triangulate(self, prim, mesh, p, counts, idx, ref: Refinement | None = None) -> Triangles:
        """The triangles of the faces that are not holes (``holeIndices``; out-of-range ones warned
        and ignored): a fan from each face's first corner where that is one, else ear clipping on
        the face's best-fit plane (:func:`~wsoft.scene.polygons.triangulate`); faces that cross
        themselves and non-planar concave faces warned, one line each per mesh. With ``ref`` (a
        refined mesh: ``p``, ``counts`` and ``idx`` are its own) the refined faces of hole faces
        (and with ``interpolateBoundary = none``, of faces touching the boundary) are left out and
        each triangle's face is its cage face."""
        ncage = len(ref.boundary_faces) if ref is not None else len(counts)
        drawn = np.ones(ncage, bool) if ref is not None else counts >= 3
        holes = self.ctx.get(mesh.GetHoleIndicesAttr())
        if holes is not None and len(holes):
            h = np.asarray(holes, dtype=np.int64)
            out_of_range = (h < 0) | (h >= ncage)
            if out_of_range.any():
                self.ctx.warn(prim, f"holeIndices: {int(out_of_range.sum())} of {len(h)} indices out of range for {ncage} faces "
                              f"(first: {int(h[out_of_range][0])}); ignored")
            drawn[h[~out_of_range]] = False
        if ref is not None:
            if self.ctx.get(mesh.GetInterpolateBoundaryAttr(), "edgeAndCorner") == "none":
                drawn &= ~ref.boundary_faces
                if not drawn.any() and ref.boundary_faces.any():
                    self.ctx.warn(prim, "interpolateBoundary = none: every face touches the boundary, where the surface has no limit; "
                                  "nothing drawn")
            tri = triangulate(p, counts, idx, keep=drawn[ref.parent])
            tri.faces = ref.parent[tri.faces]
        else:
            tri = triangulate(p, counts, idx, keep=drawn)
        if tri.non_planar:
            self.ctx.warn(prim, f"{tri.non_planar} concave faces are not planar (up to {tri.off_plane:.3g} off their best-fit plane): "
                          "triangulated on that plane")
        if tri.self_intersecting:
            self.ctx.warn(prim, f"{tri.self_intersecting} faces cross themselves: triangulated as a fan from their first corner")
        return tri

    def refinement(self, prim, mesh, p, counts, idx) -> Refinement | None:
        """The mesh refined ``subdiv_level`` times when it is a subdivision surface
        (:func:`wsoft.scene.subdiv.refine`), else None (a polygon mesh, or level 0: its cage). Its
        scheme is ``subdivisionScheme`` (unauthored: catmullClark, USD's fallback); its sharp
        features are read by :meth:`subdivision_tags`. A loop mesh with a face that is not a
        triangle, or one refined into more than :data:`~wsoft.scene.subdiv.MAX_FACES` faces, is an
        error naming the prim."""
        attr = mesh.GetSubdivisionSchemeAttr()
        scheme = str(attr.Get(self.ctx.timecode) or "catmullClark")
        if scheme == "none":
            return None
        path = str(prim.GetPath())
        if scheme not in SCHEMES:
            self.ctx.warn(prim, f"subdivisionScheme {scheme!r} is not one of none, {', '.join(SCHEMES)}; read as a polygon mesh")
            return None
        live = int(np.count_nonzero(counts >= 3))
        if self.subdiv_level == 0:
            self.subdivision[path] = (scheme, attr.HasAuthoredValue(), live, live)
            return None
        tags = self.subdivision_tags(prim, mesh, scheme, len(p))
        try:
            ref = refine(p, counts, idx, scheme, self.subdiv_level, tags)
        except ValueError as exc:
            raise self.ctx.err(prim, str(exc)) from None
        if ref.unmatched_creases:
            self.ctx.warn(prim, f"{ref.unmatched_creases} crease edges (creaseIndices) are not edges of the mesh; ignored")
        self.subdivision[path] = (scheme, attr.HasAuthoredValue(), live, len(ref.counts))
        return ref

    def subdivision_tags(self, prim, mesh, scheme: str, npoints: int) -> Tags:
        """The mesh's ``interpolateBoundary``, creases (``creaseIndices``, ``creaseLengths``,
        ``creaseSharpnesses``) and corners (``cornerIndices``, ``cornerSharpnesses``) for
        :func:`~wsoft.scene.subdiv.refine`. Inconsistent counts and out-of-range vertices are
        warned and that part ignored; a NaN sharpness is an error. ``triangleSubdivisionRule =
        smooth`` is warned (Catmull–Clark's own rule is used)."""
        ctx = self.ctx
        boundary = str(ctx.get(mesh.GetInterpolateBoundaryAttr(), "edgeAndCorner"))
        if boundary not in BOUNDARY_MODES:
            ctx.warn(prim, f"interpolateBoundary {boundary!r} is not one of {', '.join(BOUNDARY_MODES)}; edgeAndCorner used")
            boundary = "edgeAndCorner"
        if scheme == "catmullClark" and str(ctx.get(mesh.GetTriangleSubdivisionRuleAttr(), "catmullClark")) == "smooth":
            ctx.warn(prim, "triangleSubdivisionRule = smooth is not applied; triangles follow the catmullClark rule")
        tags = Tags(boundary=boundary)
        ci = ctx.get(mesh.GetCreaseIndicesAttr())
        if ci is not None and len(ci):
            try:
                edges, sharp = crease_edges(ci, ctx.get(mesh.GetCreaseLengthsAttr()), ctx.get(mesh.GetCreaseSharpnessesAttr()))
            except ValueError as exc:
                ctx.warn(prim, f"{exc}; creases ignored")
            else:
                self._check_sharpness(prim, "creaseSharpnesses", sharp)
                ok = np.all((edges >= 0) & (edges < npoints), axis=1)
                if not ok.all():
                    ctx.warn(prim, f"creaseIndices: {int((~ok).sum())} crease edges name points out of range for {npoints} points; ignored")
                tags.crease_edges, tags.crease_sharpness = edges[ok], sharp[ok]
        vi = ctx.get(mesh.GetCornerIndicesAttr())
        if vi is not None and len(vi):
            vi = np.asarray(vi, np.int64)
            vs = np.asarray(ctx.get(mesh.GetCornerSharpnessesAttr(), []), np.float64)
            if len(vs) != len(vi):
                ctx.warn(prim, f"cornerSharpnesses has {len(vs)} values for {len(vi)} cornerIndices; corners ignored")
            else:
                self._check_sharpness(prim, "cornerSharpnesses", vs)
                ok = (vi >= 0) & (vi < npoints)
                if not ok.all():
                    ctx.warn(prim, f"cornerIndices: {int((~ok).sum())} of {len(vi)} out of range for {npoints} points; ignored")
                tags.corners, tags.corner_sharpness = vi[ok], vs[ok]
        return tags

    def _check_sharpness(self, prim, name: str, values: np.ndarray) -> None:
        if np.isnan(values).any():
            raise self.ctx.err(prim, f"{name}[{int(np.argmax(np.isnan(values)))}] is NaN")

    def subdivision_note(self) -> str | None:
        """One line on the subdivision surfaces read (None: there were none): at level 0 how many
        meshes were read as their control cage (and how to refine them), else how many were refined
        and into how many faces."""
        if not self.subdivision:
            return None
        schemes: dict[str, int] = {}
        for scheme, _, _, _ in self.subdivision.values():
            schemes[scheme] = schemes.get(scheme, 0) + 1
        kinds = ", ".join(f"{n} {k}" for k, n in sorted(schemes.items()))
        n = len(self.subdivision)
        if self.subdiv_level == 0:
            unauthored = sum(1 for _, authored, _, _ in self.subdivision.values() if not authored)
            fallback = f"; {'all' if unauthored == n else unauthored} by USD's fallback, subdivisionScheme unauthored" if unauthored else ""
            return (f"{self.ctx.file}: {n} mesh{'es are' if n > 1 else ' is a'} subdivision surface{'s' if n > 1 else ''} ({kinds}{fallback}; "
                    f"{'e.g. ' if n > 1 else ''}{next(iter(self.subdivision))}), loaded as {'their control cages' if n > 1 else 'its control cage'}: "
                    f"subdiv_level=N (--subdiv-level N, 1..{MAX_LEVEL}) refines {'them' if n > 1 else 'it'}; "
                    "subdivisionScheme = \"none\" marks a polygon mesh")
        cage = sum(c for _, _, c, _ in self.subdivision.values())
        faces = sum(f for _, _, _, f in self.subdivision.values())
        return (f"{self.ctx.file}: subdiv_level {self.subdiv_level}: {n} subdivision surface mesh{'es' if n > 1 else ''} ({kinds}) "
                f"refined, {cage:,} cage faces into {faces:,}")

    def texture_coords(self, prim, corners, face_of_tri, tris, mat, shape: bool = False, ref: Refinement | None = None):
        """Per triangle corner, the st its material's opacity texture is sampled at, [T, 3, 2]
        float32, and the triangles' materials. A triangle whose material reads a texture gets the
        primvar that material's network names (:class:`~wsoft.scene.types.StMap`: the
        ``UsdPrimvarReader_float2``'s ``varname``, its ``fallback`` where the mesh lacks it) mapped
        by its ``UsdTransform2d`` nodes, here on the host (exact: the map is affine); a triangle of
        a UDIM material gets the material of its tile, its st shifted into the tile
        (:meth:`udim_tiles`). Other triangles keep the ``st`` primvar (0 without one). A ``shape``
        (one of UsdGeom's) reads constant primvars only (:meth:`read_primvar`). ``ref``: the
        mesh's refinement (primvars refined with it)."""
        read: dict[str, np.ndarray | None] = {}

        def primvar(name: str):
            if name not in read:
                read[name] = self.read_primvar(prim, corners, face_of_tri, tris, name, 2, shape=shape, ref=ref)
            return read[name]

        st = primvar("st")
        uv = np.zeros((len(tris), 3, 2), np.float32) if st is None else st
        used = np.unique(mat)
        if all(self.materials[m].st is None or self.materials[m].st.primvar == "st" and self.materials[m].st.identity
               and self.materials[m].udim is None and st is not None for m in used):
            return uv, mat  # every triangle's st as the mesh holds it
        uv, mat = uv.copy(), mat.copy()
        for m in used:
            material = self.materials[m]
            stmap = material.st
            if stmap is None:
                continue
            sel = mat == m
            src = primvar(stmap.primvar) if stmap.primvar else None
            if src is None:
                if stmap.primvar:
                    self.ctx.warn(prim, f"has no primvars:{stmap.primvar} (read by {stmap.reader}); {material.path} reads the reader's "
                                  f"fallback st = ({stmap.fallback[0]:g}, {stmap.fallback[1]:g}) there")
                base = np.broadcast_to(np.asarray(stmap.fallback, np.float32), (int(sel.sum()), 3, 2))
            else:
                base = src[sel]
            if not stmap.identity or src is None:
                a = np.asarray(stmap.matrix, np.float64)
                base = (base.astype(np.float64) @ a[:, :2].T + a[:, 2]).astype(np.float32)
            uv[sel] = base
            if material.udim is not None:
                self.udim_tiles(prim, int(m), sel, uv, mat)
        return uv, mat

    def udim_tiles(self, prim, m: int, sel, uv, mat) -> None:
        """Give the triangles ``sel`` of the UDIM material ``m`` the material of the tile their st
        centroid lies in (tile 1001 + u + 10 v for st in [u, u + 1) x [v, v + 1), u and v in 0..9)
        and shift their st into it (``uv`` and ``mat`` in place). Triangles spanning tiles read their
        centroid's tile, clamped at its edge; those in no tile, the texture's fallback (warnings)."""
        material = self.materials[m]
        t = uv[sel].astype(np.float64)
        cell = np.floor(t.mean(axis=1))  # [n, 2]
        inside = np.all((cell >= 0) & (cell <= 9), axis=1)
        tile = np.where(inside, 1001 + cell[:, 0] + 10 * cell[:, 1], -1).astype(np.int64)
        local = t - np.where(inside[:, None], cell, 0.0)[:, None, :]
        eps = 1e-6
        spans = inside & np.any((local < -eps) | (local > 1 + eps), axis=(1, 2))
        if spans.any():
            self.ctx.warn(prim, f"{int(spans.sum())} triangles span UDIM tiles of {material.path}; each reads the tile of its centroid, "
                          "clamped at its edge")
        if not inside.all():
            self.ctx.warn(prim, f"{int((~inside).sum())} triangles of {material.path} have st outside the UDIM tiles 1001-1100; "
                          f"they take the texture's fallback {material.fallback:g}")
        missing = sorted({int(k) for k in np.unique(tile[inside]) if int(k) not in material.udim})
        if missing:
            self.ctx.warn(prim, f"UDIM tiles {', '.join(map(str, missing[:5]))}{' ...' if len(missing) > 5 else ''} of {material.path} "
                          f"have no file; their triangles take the texture's fallback {material.fallback:g}")
        uv[sel] = local.astype(np.float32)
        idx = np.flatnonzero(sel)
        for k in np.unique(tile):
            key = (m, int(k))
            if key not in self.tile_index:
                tex = material.udim.get(int(k), -1)
                self.tile_index[key] = len(self.materials)
                self.materials.append(replace(material, texture=tex, opacity=1.0 if tex >= 0 else material.fallback, st=None, udim=None,
                                              tile=int(k)))
            mat[idx[tile == k]] = self.tile_index[key]

    def read_primvar(self, prim, corners, face_of_tri, tris, name: str, width: int, shape: bool = False,
                     ref: Refinement | None = None):
        """A primvar's values at each triangle corner, shape [T, 3, width]; None when absent. On a
        ``shape`` (one of UsdGeom's, tessellated here) only a constant primvar has a meaning: any
        other interpolation is warned about and ignored. On a refined mesh (``ref``; ``corners`` and
        ``tris`` are the refined mesh's, ``face_of_tri`` the cage's faces) ``vertex`` values are refined
        by the scheme's rules, ``varying`` ones linearly and ``faceVarying`` ones bilinearly in each
        face (:class:`~wsoft.scene.subdiv.Refinement`)."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        if not pv or not pv.HasValue():
            return None
        vals = pv.ComputeFlattened(self.ctx.timecode)
        if vals is None or len(vals) == 0:
            return None
        v = np.asarray(vals, dtype=np.float32)
        if v.ndim == 1 and len(v) == width:  # one value of a non-array type
            v = v[None]
        if v.ndim != 2 or v.shape[1] != width:
            self.ctx.warn(prim, f"primvars:{name} is {pv.GetTypeName()}, not {width} numbers per element; ignored")
            return None
        interp = pv.GetInterpolation()
        if shape and interp != UsdGeom.Tokens.constant:
            line = (f"{self.ctx.file}: {prim.GetPath()}: primvars:{name} has {interp} interpolation, but a {prim.GetTypeName()} has "
                    "no authored faces or points to vary over; ignored")
            if line not in self.ctx.warnings:
                self.ctx.warnings.append(line)
            return None
        if ref is not None and interp in (UsdGeom.Tokens.faceVarying, UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
            need = len(ref.cage_corners) if interp == UsdGeom.Tokens.faceVarying else ref.cage_points
            if len(v) < need:
                raise self.ctx.err(prim, f"primvars:{name} has {len(v)} values, too few for {interp} interpolation")
            v = v[:need].astype(np.float64)
            v = (ref.face_varying(v) if interp == UsdGeom.Tokens.faceVarying else ref.vertex(v) if interp == UsdGeom.Tokens.vertex
                 else ref.varying(v)).astype(np.float32)
        try:
            if interp == UsdGeom.Tokens.faceVarying:
                out = v[corners]
            elif interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
                out = v[tris]
            elif interp == UsdGeom.Tokens.uniform:
                out = np.repeat(v[face_of_tri][:, None, :], 3, axis=1)
            else:  # constant
                out = np.broadcast_to(v[0], (len(tris), 3, width)).copy()
        except IndexError:
            raise self.ctx.err(prim, f"primvars:{name} has {len(v)} values, too few for {interp} interpolation") from None
        return out.astype(np.float32)

    def bind_materials(self, prim, mesh, nfaces: int, face_of_tri):
        """Per triangle, the material bound to the gprim, or to the ``GeomSubset`` of its face (a
        ``UsdGeom.Mesh`` ``mesh``; a shape, ``mesh`` None, has no faces a subset could name)."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        face_mat = np.full(nfaces, self.material_for(prim), np.int32)
        subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets() if mesh is not None else []
        for subset in subsets:
            ind = self.ctx.get(subset.GetIndicesAttr())
            if ind is None:
                continue
            ind = np.asarray(ind, dtype=np.int64)
            if len(ind) and (ind.min() < 0 or ind.max() >= nfaces):
                raise self.ctx.err(subset.GetPrim(), f"GeomSubset face index out of range for {nfaces} faces")
            face_mat[ind] = self.material_for(subset.GetPrim())
        return face_mat[face_of_tri]

    def material_for(self, prim) -> int:
        material = self.ctx.bound_material(prim)
        if not material:
            color = self.display_color(prim)
            if color is None:
                return 0
            key = f"(displayColor){color}"
            if key not in self.material_index:
                self.material_index[key] = len(self.materials)
                self.materials.append(Material(path=key, albedo=color))
            return self.material_index[key]
        mpath = str(material.GetPath())
        if mpath not in self.material_index:
            self.material_index[mpath] = len(self.materials)
            self.materials.append(self.read_material(material))
        return self.material_index[mpath]

    def display_color(self, prim):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        if not prim.IsA(UsdGeom.Gprim):
            return None
        pv = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        if pv and pv.HasValue():
            v = pv.ComputeFlattened(self.ctx.timecode)
            if v is not None and len(v):
                c = np.asarray(v, dtype=np.float64).reshape(-1, 3).mean(axis=0)
                return tuple(float(x) for x in np.clip(c, 0, 1))
        return None

    def read_material(self, material) -> Material:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        mat = Material(path=str(material.GetPath()))
        shader = material.ComputeSurfaceSource()[0]
        if not shader:
            return mat
        sid = shader.GetShaderId()
        if sid != "UsdPreviewSurface":
            self.ctx.warn(material.GetPrim(), f"surface shader {shader.GetPath()} ({sid or 'no info:id'}) is not UsdPreviewSurface; "
                          "treated as opaque grey")
            return mat
        diffuse = shader.GetInput("diffuseColor")
        if diffuse and not diffuse.HasConnectedSource():
            v = diffuse.Get(self.ctx.timecode)
            if v is not None:
                mat.albedo = tuple(float(x) for x in v)
        self.network.read(shader, mat)
        return mat


def closed_orientation(points: np.ndarray, tris: np.ndarray) -> int:
    """+1 if the triangles form a closed, consistently wound surface facing outward, -1 if it
    faces inward, 0 if it is open, non-manifold or inconsistently wound.

    Closed: every directed edge (a, b) appears once and its reverse (b, a) appears once. For
    such a surface the nearest hit along any ray from outside is a face turned toward the ray,
    which lets the light-view rasterizer skip the faces turned away (exactly).
    """
    if len(tris) < 4:
        return 0
    n = int(points.shape[0])
    a = tris.astype(np.int64)
    fwd = np.concatenate([a[:, 0] * n + a[:, 1], a[:, 1] * n + a[:, 2], a[:, 2] * n + a[:, 0]])
    rev = np.concatenate([a[:, 1] * n + a[:, 0], a[:, 2] * n + a[:, 1], a[:, 0] * n + a[:, 2]])
    fwd.sort()
    if np.any(fwd[1:] == fwd[:-1]):
        return 0
    rev.sort()
    if not np.array_equal(fwd, rev):
        return 0
    p = points[a].astype(np.float64)
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    scale = float(np.ptp(points, axis=0).max()) ** 3 if len(points) else 0.0
    if abs(vol) <= 1e-9 * max(scale, 1e-30):
        return 0
    return 1 if vol > 0 else -1
