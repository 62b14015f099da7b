"""USD instancing: PointInstancers and instanceable prims, flattened or kept instanced.

Flat (the default load), :meth:`InstanceReader.read_instancer` reads a ``UsdGeom.PointInstancer``'s
prototype meshes once per instance it places. Kept instanced (``load_scene(..., instancing=True)``),
:meth:`InstanceReader.read_instancer_instances` and :meth:`InstanceReader.read_instance` read each
prototype once, in its own frame, into an :class:`InstanceBuilder`, which collects the prototypes
(:class:`~wsoft.scene.types.Prototype`) and the instances that place them
(:class:`~wsoft.scene.types.Instances`). :func:`light_linking_instances` finds a light whose shadow
linking an instanced load cannot keep.
"""

from __future__ import annotations

import numpy as np

from wsoft.scene.shapes import not_drawn, shape_type
from wsoft.scene.soup import MeshPart, Soup
from wsoft.scene.types import Instances, Prototype
from wsoft.scene.usd_context import StageContext, pxr
from wsoft.scene.usd_lights import HANDLED_LIGHTS
from wsoft.scene.usd_mesh import MeshReader


def placed_apart(prim, UsdGeom, UsdLux) -> bool:
    """Is ``prim`` something an instanceable prim's prototype cannot keep instanced: a light, a
    camera or a PointInstancer?"""
    type_name = prim.GetTypeName()
    return (prim.IsA(UsdGeom.Camera) or prim.IsA(UsdGeom.PointInstancer) or prim.HasAPI(UsdLux.LightAPI)
            or type_name in HANDLED_LIGHTS or type_name.endswith("Light"))


class InstanceBuilder:
    """The instances a load keeps (``load_scene(..., instancing=True)``) as the reader finds them:
    prototypes by key, and per instance its prototype, transform, prim, id and dynamic flag. Shares
    the reader's ``prims`` and ``prim_points`` lists (prototype meshes and instance prims get empty
    ``prim_points`` rows: their points are not in the soup)."""

    def __init__(self, prims: list[str], prim_points: list):
        self.prims, self.prim_points = prims, prim_points
        self.prim_index: dict[str, int] = {}
        self.prototypes: list[Prototype] = []
        self.proto_of: dict[tuple, int] = {}  # key -> index into prototypes (-1: no triangles)
        self.scan: dict[str, tuple | None] = {}  # USD prototype path -> (mesh paths, other gprims) relative to the instance, None: read flat
        self.proto, self.xform, self.prim, self.ids, self.dynamic = [], [], [], [], []

    @property
    def count(self) -> int:
        return sum(len(p) for p in self.proto)

    def add_prim(self, name: str) -> int:
        if name not in self.prim_index:
            self.prims.append(name)
            self.prim_points.append((0, 0))
            self.prim_index[name] = len(self.prims) - 1
        return self.prim_index[name]

    def add_prototype(self, key, path: str, root: str, meshes: list[tuple[MeshPart, str]]) -> None:
        """Prototype ``key`` from the meshes read (each with its prim's name), -1 when none."""
        if not meshes:
            self.proto_of[key] = -1
            return
        soup = Soup()
        for mesh, name in meshes:
            soup.add(mesh, self.add_prim(name))
        fields = soup.arrays()
        if not fields["tri_dynamic"].any():
            fields["tri_dynamic"] = None
        self.proto_of[key] = len(self.prototypes)
        self.prototypes.append(Prototype(path=path, root=root, prim_points=np.asarray(soup.point_ranges, np.int64).reshape(-1, 3), **fields))

    def add(self, proto: np.ndarray, xform: np.ndarray, prim: int, ids: np.ndarray, dynamic: bool) -> None:
        self.proto.append(np.asarray(proto, np.int32))
        self.xform.append(np.asarray(xform, np.float64).reshape(-1, 4, 4))
        self.prim.append(np.full(len(proto), prim, np.int32))
        self.ids.append(np.asarray(ids, np.int32))
        self.dynamic.append(np.full(len(proto), bool(dynamic), bool))

    def instances(self) -> Instances:
        return Instances(prototypes=self.prototypes, proto=np.concatenate(self.proto), xform=np.concatenate(self.xform),
                         prim=np.concatenate(self.prim), instance_id=np.concatenate(self.ids), dynamic=np.concatenate(self.dynamic))

    def flat_paths(self) -> set[tuple[str, ...]]:
        """The prim paths a flat load's instanced meshes answer to in a shadowLink test: (the
        prototype mesh, the PointInstancer) for an instancer's, (the instance proxy) for an
        instanceable prim's."""
        out = set()
        for proto_k, prim_k, ids_k in zip(self.proto, self.prim, self.ids):
            for pj, where, iid in {(int(a), int(b), int(c) >= 0) for a, b, c in zip(proto_k, prim_k, ids_k)}:
                proto = self.prototypes[pj]
                for m in np.unique(proto.tri_prim):
                    name = self.prims[int(m)]
                    if iid:
                        out.add((name, self.prims[where]))
                    else:
                        out.add((self.prims[where] + name[len(proto.root):],))
        return out


class InstanceReader:
    """The instancing prims of one stage, their prototypes' meshes read by ``meshes``."""

    def __init__(self, ctx: StageContext, meshes: MeshReader):
        self.ctx = ctx
        self.meshes = meshes

    def instancer_parts(self, prim):
        """What a ``UsdGeom.PointInstancer`` places, checked: (protoIndices [N] int64, USD's instance
        transforms (``ComputeInstanceTransformsAtTime``: positions, orientations, scales, the
        prototypes' own transforms; row-vector matrices), shown [N] bool (the mask of
        ``invisibleIds`` and inactive ids), the instancer's world matrix, moving (its instances move
        over time), {prototype index: (root prim, its meshes)}); None when it places nothing."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        pi = UsdGeom.PointInstancer(prim)
        protos = pi.GetPrototypesRel().GetForwardedTargets()
        indices = self.ctx.get(pi.GetProtoIndicesAttr())
        if indices is None or len(indices) == 0:
            return None
        indices = np.asarray(indices, np.int64)
        if not protos:
            raise self.ctx.err(prim, f"PointInstancer has {len(indices)} instances but no prototypes")
        if indices.min() < 0 or indices.max() >= len(protos):
            bad = int(np.argmax((indices < 0) | (indices >= len(protos))))
            raise self.ctx.err(prim, f"protoIndices[{bad}] = {int(indices[bad])} is out of range for {len(protos)} prototypes")
        xforms = pi.ComputeInstanceTransformsAtTime(self.ctx.timecode, self.ctx.timecode, UsdGeom.PointInstancer.IncludeProtoXform,
                                                    UsdGeom.PointInstancer.IgnoreMask)
        if xforms is None or len(xforms) != len(indices):
            raise self.ctx.err(prim, f"PointInstancer's positions/orientations/scales do not match its {len(indices)} protoIndices")
        mask = pi.ComputeMaskAtTime(self.ctx.timecode)  # empty: every instance shows
        keep = np.ones(len(indices), bool) if mask is None or len(mask) == 0 else np.asarray(mask, bool)
        M_pi = self.ctx.world(prim)
        # dynamic when the instancer's values may vary over time, its instances move by velocity (is_dynamic), or it is moved
        attrs = (pi.GetPositionsAttr(), pi.GetOrientationsAttr(), pi.GetScalesAttr(), pi.GetProtoIndicesAttr(), pi.GetInvisibleIdsAttr())
        moving = any(a and a.ValueMightBeTimeVarying() for a in attrs) or self.ctx.is_dynamic(prim)
        meshes_of = {}
        for j, path in enumerate(protos):
            root = self.ctx.stage.GetPrimAtPath(path)
            if not root:
                raise self.ctx.err(prim, f"prototype {path} does not exist")
            found = []
            sub = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
            for q in sub:
                if q.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(q).ComputeVisibility(self.ctx.timecode) == UsdGeom.Tokens.invisible:
                    sub.PruneChildren()
                    continue
                if q.IsA(UsdGeom.PointInstancer):
                    self.ctx.warn(q, "a PointInstancer inside a prototype is not expanded; ignored")
                    sub.PruneChildren()
                elif q.IsA(UsdGeom.Mesh) or shape_type(q):
                    found.append(q)
                elif q.IsA(UsdGeom.Gprim):
                    self.ctx.warn(q, not_drawn(q.GetTypeName()))
            meshes_of[j] = (root, found)
        return indices, xforms, keep, M_pi, moving, meshes_of

    def read_instancer(self, prim):
        """The meshes a ``UsdGeom.PointInstancer`` places, one copy per instance (flattened): the
        instance transforms from USD's own ``ComputeInstanceTransformsAtTime`` (positions,
        orientations, scales, the prototypes' own transforms) with the mask of ``invisibleIds``
        and inactive ids applied to them and to ``protoIndices``, each prototype's meshes read
        once per instance. Yields (mesh, name) with name ``mesh@instancer[i]``."""
        parts = self.instancer_parts(prim)
        if parts is None:
            return
        indices, xforms, keep, M_pi, moving, meshes_of = parts
        for i in np.nonzero(keep)[0]:
            root, found = meshes_of[int(indices[i])]
            # the instance transform maps the prototype root's own frame (its xform included) into the
            # instancer's; the meshes below the root keep their transforms relative to it
            self.ctx.world_override = (root, M_pi @ np.array(xforms[int(i)], dtype=np.float64).T)
            try:
                for q in found:
                    mesh = self.meshes.read(q)
                    if mesh is not None:
                        if moving:
                            mesh = mesh._replace(dynamic=True)
                        yield mesh, f"{q.GetPath()}@{prim.GetPath()}[{int(i)}]"
            finally:
                self.ctx.world_override = None

    def read_instancer_instances(self, prim, inst: InstanceBuilder) -> None:
        """A ``UsdGeom.PointInstancer`` kept instanced (``instancing``): the checks of
        :meth:`instancer_parts`, each prototype a placed instance uses read once in its root's frame
        (shared by every instancer that names the same root), one instance per shown id with
        world(instancer) @ USD's instance transform, dynamic when the instancer moves its instances."""
        parts = self.instancer_parts(prim)
        if parts is None:
            return
        indices, xforms, keep, M_pi, moving, meshes_of = parts
        shown = np.flatnonzero(keep)
        if not len(shown):
            return
        protos = np.full(len(meshes_of), -1, np.int64)
        for j in np.unique(indices[shown]):
            root, found = meshes_of[int(j)]
            key = ("PointInstancer", str(root.GetPath()))
            if key not in inst.proto_of:
                self.ctx.world_override = (root, np.eye(4))  # the root's own frame
                try:
                    meshes = [(m, str(q.GetPath())) for q in found for m in [self.meshes.read(q)] if m is not None]
                finally:
                    self.ctx.world_override = None
                inst.add_prototype(key, str(root.GetPath()), str(root.GetPath()), meshes)
            protos[j] = inst.proto_of[key]
        X = np.array([np.array(xforms[int(i)], dtype=np.float64).T for i in shown]).reshape(-1, 4, 4)
        W = M_pi @ X
        placed = protos[indices[shown]] >= 0  # a prototype without triangles places nothing
        if placed.any():
            where = inst.add_prim(str(prim.GetPath()))
            inst.add(protos[indices[shown]][placed], W[placed], where, shown[placed], moving)

    def read_instance(self, prim, inst: InstanceBuilder) -> bool:
        """An instanceable prim kept instanced (``instancing``): its USD prototype's meshes, read once
        through the proxies of the first instance that resolves them alike (material bindings and
        purposes resolve on the proxies, and may come from above the instance), in the instance
        prim's frame; nested instances inside are flattened into it. False (read it as when flat)
        for an invisible prim, one that is itself a mesh, light, camera or PointInstancer, or one
        whose prototype holds a light, a camera or a PointInstancer."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        if prim.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(prim).ComputeVisibility(self.ctx.timecode) == UsdGeom.Tokens.invisible:
            return False
        if prim.IsA(UsdGeom.Gprim) or placed_apart(prim, UsdGeom, UsdLux):
            return False
        ppath = str(prim.GetPrototype().GetPath())
        ipath = prim.GetPath()
        if ppath not in inst.scan:
            meshes, others, mixed = [], [], False
            sub = iter(Usd.PrimRange(prim, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
            next(sub)  # the instance prim itself
            for q in sub:
                if q.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(q).ComputeVisibility(self.ctx.timecode) == UsdGeom.Tokens.invisible:
                    sub.PruneChildren()
                    continue
                if placed_apart(q, UsdGeom, UsdLux):
                    mixed = True
                    break
                if q.IsA(UsdGeom.Mesh) or shape_type(q):
                    meshes.append(q.GetPath().MakeRelativePath(ipath))
                elif q.IsA(UsdGeom.Gprim):
                    others.append(q.GetPath().MakeRelativePath(ipath))
            inst.scan[ppath] = None if mixed else (meshes, others)
        scan = inst.scan[ppath]
        if scan is None:
            return False
        meshes, others = scan
        # how this instance resolves its prototype's meshes: purpose included, materials bound
        resolved, proxies = [], []
        for rel in meshes:
            q = self.ctx.stage.GetPrimAtPath(ipath.AppendPath(rel))
            if UsdGeom.Imageable(q).ComputePurpose() not in self.ctx.purposes:
                resolved.append(None)
                continue
            subsets = UsdShade.MaterialBindingAPI(q).GetMaterialBindSubsets()
            resolved.append((self.material_key(q, ipath), *(self.material_key(g.GetPrim(), ipath) for g in subsets)))
            proxies.append(q)
        key = (ppath, tuple(resolved))
        if key not in inst.proto_of:
            for rel in others:
                q = self.ctx.stage.GetPrimAtPath(ipath.AppendPath(rel))
                if UsdGeom.Imageable(q).ComputePurpose() in self.ctx.purposes:
                    self.ctx.warn(q, not_drawn(q.GetTypeName()))
            self.ctx.world_override, self.ctx.dynamic_stop = (prim, np.eye(4)), prim  # the instance prim's frame
            try:
                read = [(m, str(q.GetPath())) for q in proxies for m in [self.meshes.read(q)] if m is not None]
            finally:
                self.ctx.world_override, self.ctx.dynamic_stop = None, None
            inst.add_prototype(key, ppath, str(ipath), read)
        j = inst.proto_of[key]
        if j < 0:
            return True  # nothing of it to draw
        M = self.ctx.world(prim)
        if not np.all(np.isfinite(M)):
            raise self.ctx.err(prim, "world transform is not finite (NaN or inf in its xformOps or an ancestor's)")
        inst.add(np.array([j]), M[None], inst.add_prim(str(ipath)), np.array([-1]), self.ctx.is_dynamic(prim))
        return True

    def material_key(self, prim, ipath):
        """How an instance proxy's material binding tells prototypes apart: a material inside the
        instance by its path relative to the instance prim (every instance has its own proxy of it,
        the same material), any other by its index in the scene's materials."""
        material = self.ctx.bound_material(prim)
        if material and material.GetPath().HasPrefix(ipath):
            return str(material.GetPath().MakeRelativePath(ipath))
        return self.meshes.material_for(prim)


def light_linking_instances(shadow_lights, inst: InstanceBuilder) -> str | None:
    """The first shadow-casting light whose ``collection:shadowLink`` leaves out a caster of the
    flat load (a soup prim, an instanced mesh as the flat loader names it), or None."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    paths = None
    for lp, light in shadow_lights:
        if light.shadow_excluded:
            return str(lp.GetPath())
        link = UsdLux.LightAPI(lp).GetShadowLinkCollectionAPI()
        if not link:
            continue
        query = link.ComputeMembershipQuery()
        paths = inst.flat_paths() if paths is None else paths
        if not all(query.IsPathIncluded(Sdf.Path(q)) for group in paths for q in group):
            return str(lp.GetPath())
    return None
