"""USD meshes with their materials and alpha textures -> :class:`~wsoft.scene.soup.MeshPart`.

:class:`MeshReader` reads a ``UsdGeom.Mesh`` at the context's time code (:mod:`wsoft.scene.usd_context`):
its faces triangulated (:mod:`wsoft.scene.polygons`; the faces of ``holeIndices`` left out), its
points placed in the world, its texture coordinates and ``primvars:wsoft:bakedLight`` per corner, and per triangle the material bound to the mesh or its
``GeomSubset`` faces. Materials (``UsdPreviewSurface``: diffuse colour, opacity, opacityThreshold, an
opacity texture through ``UsdUVTexture``, or a prim's ``displayColor`` without one) and textures are
read once each and kept in :attr:`MeshReader.materials` and :attr:`MeshReader.textures`.
:func:`closed_orientation` tells a closed surface (whose far faces the light view may skip).
"""

from __future__ import annotations

import numpy as np

from wsoft.scene.polygons import Triangles, triangulate
from wsoft.scene.soup import MeshPart
from wsoft.scene.types import WRAP_NAMES, Material, Texture
from wsoft.scene.usd_context import StageContext, pxr


class MeshReader:
    """Meshes of one stage, and the materials and textures they use (index 0: the default material)."""

    def __init__(self, ctx: StageContext):
        self.ctx = ctx
        self.materials: list[Material] = [Material(path="(default)")]
        self.material_index: dict[str, int] = {"": 0}
        self.textures: list[Texture] = []
        self.texture_index: dict[tuple, int] = {}
        self.prototype_triangles: dict[str, Triangles] = {}  # a PointInstancer prototype's mesh path -> its triangles

    def read_mesh(self, prim) -> MeshPart | None:
        """The mesh ``prim`` triangulated (:func:`~wsoft.scene.polygons.triangulate`: a fan from each
        face's first corner, concave faces ear-clipped; the faces of ``holeIndices`` left out;
        ``orientation`` respected, the winding flipped under a mirroring transform) in the world (or
        the frame of the context's ``world_override``), zero-area triangles dropped; None (with a
        warning) when nothing is left. Faces that cross themselves, non-planar concave faces and
        out-of-range hole indices are warned once per mesh."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        mesh = UsdGeom.Mesh(prim)
        points = self.ctx.get(mesh.GetPointsAttr())
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

        # a prototype a PointInstancer places many times is triangulated (and warned about) once
        key = str(prim.GetPath()) if self.ctx.world_override is not None else None
        tri = self.prototype_triangles.get(key) if key is not None else None
        if tri is None:
            tri = self.triangulate(prim, mesh, p, counts, idx)
            if key is not None:
                self.prototype_triangles[key] = tri
        corners, face_of_tri = tri.corners, tri.faces
        orient = self.ctx.get(mesh.GetOrientationAttr(), UsdGeom.Tokens.rightHanded)
        if orient == UsdGeom.Tokens.leftHanded:
            corners = corners[:, [0, 2, 1]]
        tris = idx[corners]

        # world transform
        M = self.ctx.world(prim)
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
        uv = self.read_st(prim, mesh, corners, face_of_tri, tris)
        mat = self.bind_materials(prim, mesh, len(counts), face_of_tri)
        ds = bool(self.ctx.get(mesh.GetDoubleSidedAttr(), False))  # UsdGeom's uniform doubleSided (the eye view's back-face culling)
        stray = prim.GetAttribute("primvars:doubleSided")
        if stray and stray.HasAuthoredValue():
            self.ctx.warn(prim, "primvars:doubleSided is not a UsdGeom property; ignored (the mesh's doubleSided attribute "
                          f"is read: {str(ds).lower()})")
        baked = self.read_primvar(prim, corners, face_of_tri, tris, "wsoft:bakedLight", 3)
        return MeshPart(points=pw, triangles=tris.astype(np.int32), material=mat, uv=uv, double_sided=ds, closed=closed_orientation(pw, tris),
                        dynamic=self.ctx.is_dynamic(prim, mesh), baked=baked, faces=face_of_tri)

    def triangulate(self, prim, mesh, p, counts, idx) -> Triangles:
        """The triangles of the faces that are not holes (``holeIndices``; out-of-range ones warned
        and ignored): a fan from each face's first corner where that is one, else ear clipping on
        the face's best-fit plane (:func:`~wsoft.scene.polygons.triangulate`); faces that cross
        themselves and non-planar concave faces warned, one line each per mesh."""
        drawn = counts >= 3
        holes = self.ctx.get(mesh.GetHoleIndicesAttr())
        if holes is not None and len(holes):
            h = np.asarray(holes, dtype=np.int64)
            out_of_range = (h < 0) | (h >= len(counts))
            if out_of_range.any():
                self.ctx.warn(prim, f"holeIndices: {int(out_of_range.sum())} of {len(h)} indices out of range for {len(counts)} faces "
                              f"(first: {int(h[out_of_range][0])}); ignored")
            drawn[h[~out_of_range]] = False
        tri = triangulate(p, counts, idx, keep=drawn)
        if tri.non_planar:
            self.ctx.warn(prim, f"{tri.non_planar} concave faces are not planar (up to {tri.off_plane:.3g} off their best-fit plane): "
                          "triangulated on that plane")
        if tri.self_intersecting:
            self.ctx.warn(prim, f"{tri.self_intersecting} faces cross themselves: triangulated as a fan from their first corner")
        return tri

    def read_st(self, prim, mesh, corners, face_of_tri, tris, name: str = "st"):
        out = self.read_primvar(prim, corners, face_of_tri, tris, name, 2)
        return np.zeros((len(tris), 3, 2), np.float32) if out is None else out

    def read_primvar(self, prim, corners, face_of_tri, tris, name: str, width: int):
        """A primvar's values at each triangle corner, shape [T, 3, width]; None when absent."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        if not pv or not pv.HasValue():
            return None
        vals = pv.ComputeFlattened(self.ctx.timecode)
        if vals is None or len(vals) == 0:
            return None
        v = np.asarray(vals, dtype=np.float32).reshape(-1, width)
        interp = pv.GetInterpolation()
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
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        face_mat = np.full(nfaces, self.material_for(prim), np.int32)
        subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
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
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
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
        sid = shader.GetIdAttr().Get() if shader.GetIdAttr() else None
        if sid != "UsdPreviewSurface":
            self.ctx.warn(material.GetPrim(), f"surface shader {sid!r} is not UsdPreviewSurface; treated as opaque grey")
            return mat
        diffuse = shader.GetInput("diffuseColor")
        if diffuse and not diffuse.HasConnectedSource():
            v = diffuse.Get(self.ctx.timecode)
            if v is not None:
                mat.albedo = tuple(float(x) for x in v)
        thr = shader.GetInput("opacityThreshold")
        mat.opacity_threshold = float(thr.Get(self.ctx.timecode) or 0.0) if thr else 0.0
        op = shader.GetInput("opacity")
        if not op:
            return mat
        if op.HasConnectedSource():
            src, out_name, _ = op.GetConnectedSource()
            tex_shader = UsdShade.Shader(src.GetPrim())
            tid = tex_shader.GetIdAttr().Get() if tex_shader and tex_shader.GetIdAttr() else None
            if tid != "UsdUVTexture":
                self.ctx.warn(material.GetPrim(), f"opacity is connected to {tid!r}, not a UsdUVTexture; treated as opaque")
                return mat
            if mat.opacity_threshold <= 0.0:
                self.ctx.warn(material.GetPrim(), "textured opacity without opacityThreshold (translucency) is not modelled; opaque")
                return mat
            mat.texture = self.read_texture(tex_shader, str(out_name), material.GetPrim())
        else:
            v = op.Get(self.ctx.timecode)
            mat.opacity = float(v) if v is not None else 1.0
            if mat.opacity < 1.0 and mat.opacity_threshold <= 0.0:
                self.ctx.warn(material.GetPrim(), f"constant opacity {mat.opacity:g} (translucency): opaque for every technique but salzman (its transparency component)")
        return mat

    def read_texture(self, tex_shader, channel: str, mat_prim) -> int:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        file_in = tex_shader.GetInput("file")
        asset = file_in.Get(self.ctx.timecode) if file_in else None
        if asset is None:
            self.ctx.warn(tex_shader.GetPrim(), "UsdUVTexture has no file; surface is opaque")
            return -1
        resolved = asset.resolvedPath or ""
        wraps = []
        for nm in ("wrapS", "wrapT"):
            w = tex_shader.GetInput(nm)
            wv = str(w.Get(self.ctx.timecode)) if w and w.Get(self.ctx.timecode) is not None else "useMetadata"
            wraps.append(WRAP_NAMES.get(wv, 0))
        key = (resolved or asset.path, channel, tuple(wraps))
        if key in self.texture_index:
            return self.texture_index[key]
        data = _read_asset(resolved) if resolved else None  # through USD's asset resolver: files inside a .usdz too
        if data is None:
            self.ctx.warn(tex_shader.GetPrim(), f"texture {asset.path!r} not found; surface is opaque")
            return -1
        try:
            import io

            from PIL import Image

            with Image.open(io.BytesIO(data)) as im:
                im.load()  # a truncated file fails here, not later
                rgba = _rgba01(im)
        except Exception as exc:
            self.ctx.warn(tex_shader.GetPrim(), f"texture {asset.path!r} cannot be read ({' '.join(str(exc).split())}); surface is opaque")
            return -1
        ch = {"r": 0, "g": 1, "b": 2, "a": 3}.get(channel, 3)
        data = np.ascontiguousarray(rgba[::-1, :, ch])  # bottom-up rows: st (0,0) = lower-left
        self.textures.append(Texture(asset=asset.path, data=data, wrap_s=wraps[0], wrap_t=wraps[1]))
        self.texture_index[key] = len(self.textures) - 1
        return len(self.textures) - 1


def _read_asset(resolved: str) -> bytes | None:
    """The bytes of a resolved asset path (a file, or a file inside a package such as
    ``scene.usdz[textures/a.png]``), read through USD's asset resolver; None when absent."""
    from pxr import Ar

    try:
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    except Exception:
        return None
    if asset is None:
        return None
    buf = asset.GetBuffer()
    return None if buf is None else bytes(buf)


def _rgba01(im) -> np.ndarray:
    """An image's RGBA in [0, 1], whatever its bit depth (8- and 16-bit, palette, grey, float)."""
    if im.mode in ("I;16", "I;16B", "I;16L", "I"):
        a = np.asarray(im, dtype=np.float64)
        top = 65535.0 if im.mode.startswith("I;16") or a.max(initial=0) > 255 else 255.0
        g = np.clip(a / top, 0.0, 1.0).astype(np.float32)
        return np.stack([g, g, g, np.ones_like(g)], axis=-1)
    if im.mode == "F":
        g = np.clip(np.asarray(im, dtype=np.float32), 0.0, 1.0)
        return np.stack([g, g, g, np.ones_like(g)], axis=-1)
    return np.asarray(im.convert("RGBA"), dtype=np.float32) / 255.0


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
