"""UsdSkel: the meshes a skeleton deforms, posed at the load's time code.

usd-core resolves what UsdSkel defines: ``UsdSkel.Cache`` finds each ``SkelRoot``'s bindings
(``skel:skeleton`` and ``skel:animationSource`` inherited down the hierarchy, instance proxies
entered), ``SkeletonQuery.ComputeSkinningTransforms`` gives the joints' skinning transforms at the
time code (the ``SkelAnimation`` mapped onto the skeleton's joints by name, joints it does not
animate at their rest pose), ``SkinningQuery`` the binding (``primvars:skel:jointIndices`` and
``jointWeights`` of any element size, constant or vertex, ``geomBindTransform``, ``skel:joints``
remapping, ``skel:skinningMethod``), and ``BlendShapeQuery`` the blend shapes (offsets,
``pointIndices``, inbetweens) weighted by the animation's ``blendShapeWeights``. The points are
skinned by :mod:`wsoft.scene.skinning`'s kernels, which match ``ComputeSkinnedPoints``.

A skinned mesh's points are in its skeleton's space: its world transform is the skeleton's, its
own transform is not used (as UsdSkel defines it). It is a dynamic caster when its joints, blend
shape weights or skeleton's transform may vary in time.

What cannot be evaluated is said, never drawn silently in the bind pose: a mesh with
``SkelBindingAPI`` joint influences and no skeleton (or outside any ``SkelRoot``) is drawn as
authored with a warning; non-finite joint weights and joint indices out of range are errors
naming the prim and the attribute; a skeleton whose animation animates none of its joints is
warned (it rests in its rest pose).
"""

from __future__ import annotations

import time as _time
import weakref
from dataclasses import dataclass

import numpy as np



@dataclass
class Posed:
    """A skinned mesh's points at the time code: ``points`` ``[N, 3]`` float64 in its skeleton's
    space, ``world`` the skeleton's local-to-world (4 x 4, column-vector convention) and whether it
    may move in time."""

    points: np.ndarray
    world: np.ndarray
    dynamic: bool


def _matrices(vt) -> np.ndarray:
    """A ``VtMatrix4dArray`` (USD's row-vector matrices) as ``[J, 4, 4]`` column-vector ones."""
    return np.array(vt, dtype=np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)


class InfluenceCache:
    """The joint influences (indices, weights) of one stage's skinned meshes whose
    ``primvars:skel:jointIndices`` and ``jointWeights`` do not vary in time, kept across loads of
    the stage (a sequence's frames) until the stage changes (``Usd.Notice.ObjectsChanged`` empties
    it). ``hits`` counts the reads it saved."""

    def __init__(self, stage):
        from pxr import Tf, Usd

        self.values: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.hits = 0
        self._listener = Tf.Notice.Register(Usd.Notice.ObjectsChanged, self._changed, stage)

    def _changed(self, notice, stage) -> None:
        self.values.clear()


_INFLUENCES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def influence_cache(stage) -> InfluenceCache:
    """The :class:`InfluenceCache` of ``stage`` (made on first use; it goes with the stage)."""
    cache = _INFLUENCES.get(stage)
    if cache is None:
        cache = _INFLUENCES[stage] = InfluenceCache(stage)
    return cache


class SkelReader:
    """The skinned meshes of ``ctx``'s stage; :meth:`pose` poses one. ``seconds`` adds up the time
    spent posing (the frame's ``skin`` pass)."""

    def __init__(self, ctx):
        from pxr import UsdSkel

        self.ctx = ctx
        self.seconds = 0.0
        self.count = 0
        self.targets: dict[str, tuple] = {}  # mesh path -> (SkeletonQuery, SkinningQuery)
        self.cache = UsdSkel.Cache()
        self.roots: set[str] = set()  # SkelRoots populated
        self.joint_sets: dict[tuple[str, str], object] = {}  # (skeleton, mesh joint order) -> JointSet at the time code

    @staticmethod
    def may_be_skinned(prim) -> bool:
        """A cheap test: ``prim`` has ``SkelBindingAPI`` or joint influences authored."""
        from pxr import UsdSkel

        return prim.HasAPI(UsdSkel.BindingAPI) or prim.HasAttribute("primvars:skel:jointIndices")

    def _populate(self, prim) -> None:
        """Read the bindings of the ``SkelRoot`` above ``prim`` (once a root)."""
        from pxr import Usd, UsdSkel

        root = UsdSkel.Root.Find(prim)
        if not root or str(root.GetPath()) in self.roots:
            return
        self.roots.add(str(root.GetPath()))
        predicate = Usd.TraverseInstanceProxies()
        self.cache.Populate(root, predicate)
        for binding in self.cache.ComputeSkelBindings(root, predicate):
            query = self.cache.GetSkelQuery(binding.GetSkeleton())
            self._check_animation(query)
            for target in binding.GetSkinningTargets():
                self.targets[str(target.GetPrim().GetPath())] = (query, target)

    def _check_animation(self, query) -> None:
        anim = query.GetAnimQuery()
        if anim and anim.GetPrim():
            joints = set(map(str, query.GetJointOrder()))
            animated = set(map(str, anim.GetJointOrder()))
            if joints and animated and not joints & animated:
                self.ctx.warn(query.GetSkeleton().GetPrim(), f"its animation {anim.GetPrim().GetPath()} animates none of its joints "
                              "(the SkelAnimation's `joints` name none of the Skeleton's); the skeleton rests in its rest pose: "
                              "name the Skeleton's joints in the animation's `joints`")

    def unbound(self, prim) -> bool:
        """``prim`` has joint influences authored but no skeleton deforms it (said as a warning)."""
        attr = prim.GetAttribute("primvars:skel:jointIndices")
        if not (attr and attr.HasAuthoredValue()):
            return False
        self.ctx.warn(prim, "has skel:jointIndices but no Skeleton deforms it (no skel:skeleton bound, or no SkelRoot above it); "
                      "drawn as authored, in its bind pose: bind a Skeleton under a SkelRoot")
        return True

    def pose(self, prim, points: np.ndarray) -> Posed | None:
        """``points`` (the mesh's authored points at the time code, ``[N, 3]``) posed by its
        skeleton; None for a mesh no skeleton deforms."""
        from pxr import Vt

        self._populate(prim)
        entry = self.targets.get(str(prim.GetPath()))
        if entry is None:
            self.unbound(prim)
            return None
        t0 = _time.perf_counter()
        query, target = entry
        tc = self.ctx.timecode
        n = len(points)
        pts = np.asarray(points, np.float64)
        if target.HasBlendShapes():
            pts = self._blend(prim, query, target, pts)
        per = int(target.GetNumInfluencesPerComponent())
        indices, weights = self._influences(prim, target, n, per)
        from wsoft.scene.skinning import JointSet, skin_points

        mapper = target.GetJointMapper()
        remapped = mapper is not None and not mapper.IsNull()
        key = (str(query.GetSkeleton().GetPath()), " ".join(map(str, target.GetJointOrder())) if remapped else "")
        joints = self.joint_sets.get(key)
        if joints is None:
            xforms = query.ComputeSkinningTransforms(tc)
            if remapped:
                xforms = mapper.RemapTransforms(xforms, Vt.Matrix4dArray(len(target.GetJointOrder())), 1)
            joints = self.joint_sets[key] = JointSet(_matrices(xforms))
        count = len(joints.joints)
        if len(indices) and (indices.min() < 0 or indices.max() >= count):
            bad = int(np.argmax((indices < 0) | (indices >= count)))
            raise self.ctx.err(prim, f"primvars:skel:jointIndices[{bad}] = {int(indices[bad])} is out of range for its "
                               f"{count} joints")
        geom_bind = np.array(target.GetGeomBindTransform(tc), np.float64).T
        skinned = skin_points(pts, geom_bind, joints, indices, weights, per, str(target.GetSkinningMethod()))
        world = self.ctx.world(query.GetSkeleton().GetPrim())
        anim = query.GetAnimQuery()
        dynamic = bool(anim and (anim.JointTransformsMightBeTimeVarying() or anim.BlendShapeWeightsMightBeTimeVarying()))
        dynamic = dynamic or self.ctx.is_dynamic(query.GetSkeleton().GetPrim())
        self.seconds += _time.perf_counter() - t0
        self.count += 1
        return Posed(points=skinned.astype(np.float64), world=world, dynamic=dynamic)

    def _influences(self, prim, target, n: int, per: int) -> tuple[np.ndarray, np.ndarray]:
        """The mesh's varying joint influences (indices, weights: ``[n * per]``), checked; read once
        while they do not vary in time (:class:`InfluenceCache`)."""
        cache = influence_cache(self.ctx.stage)
        key = str(prim.GetPath())
        got = cache.values.get(key)
        if got is not None and len(got[0]) == n * per:
            cache.hits += 1
            return got
        found = target.ComputeVaryingJointInfluences(n, self.ctx.timecode)
        if not found:
            raise self.ctx.err(prim, f"primvars:skel:jointIndices / jointWeights do not give {per} influences for each of its {n} points")
        indices, weights = (np.asarray(a) for a in found)
        if not np.all(np.isfinite(weights)):
            bad = int(np.argmax(~np.isfinite(weights)))
            raise self.ctx.err(prim, f"primvars:skel:jointWeights[{bad}] = {float(weights[bad])} is not finite")
        varying = any(pv and pv.GetAttr().ValueMightBeTimeVarying()
                      for pv in (target.GetJointIndicesPrimvar(), target.GetJointWeightsPrimvar()))
        if not varying:
            cache.values[key] = (indices, weights)
        return indices, weights

    def _blend(self, prim, query, target, pts: np.ndarray) -> np.ndarray:
        """``pts`` with the mesh's blend shapes applied at the animation's weights."""
        from pxr import UsdSkel, Vt

        anim = query.GetAnimQuery()
        if not anim:
            return pts
        weights = anim.ComputeBlendShapeWeights(self.ctx.timecode)
        if weights is None or len(weights) == 0:
            return pts
        mapper = target.GetBlendShapeMapper()
        if mapper is not None and not mapper.IsNull():
            weights = mapper.Remap(weights, Vt.FloatArray(len(target.GetBlendShapeOrder())))
        w = np.asarray(weights, np.float64)
        if not np.all(np.isfinite(w)):
            raise self.ctx.err(anim.GetPrim(), f"blendShapeWeights[{int(np.argmax(~np.isfinite(w)))}] is not finite")
        bsq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
        sub_w, shape_idx, sub_idx = bsq.ComputeSubShapeWeights(weights)
        out = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts, np.float32))
        bsq.ComputeDeformedPoints(sub_w, shape_idx, sub_idx, bsq.ComputeBlendShapePointIndices(), bsq.ComputeSubShapePointOffsets(), out)
        return np.asarray(out, np.float64)
