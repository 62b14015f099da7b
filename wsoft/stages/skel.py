"""Skinned stages: UsdSkel skeletons, animations and bound meshes, as a pipeline hands them over.

:func:`add_skeleton` writes a ``SkelRoot`` with a ``Skeleton`` (joints, bind and rest transforms)
and a ``SkelAnimation`` (translations, rotations, scales, blend-shape weights per time code), the
skeleton's ``skel:animationSource`` pointing at it; :func:`add_skinned_bar` binds a bar mesh along
+x to it with per-point joint influences. :func:`arm_stage` builds the tests' cases on a ground
under a rect light: a two-bone arm bent at its elbow, weights spread over four joints, a twist,
a blend shape with an inbetween, an ``animationSource`` inherited from an ancestor.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from wsoft.stages.builders import add_camera, add_quad, add_rect_light, make_stage


def _quat(axis, degrees: float) -> Gf.Quatf:
    r = Gf.Rotation(Gf.Vec3d(*axis), float(degrees)).GetQuat()
    return Gf.Quatf(float(r.GetReal()), Gf.Vec3f(*map(float, r.GetImaginary())))


def add_skeleton(stage: Usd.Stage, root: str, joints: list[str], offsets: list, poses: dict, *,
                 blend_shapes: list[str] | None = None, blend_weights: dict | None = None, bind_anim_on: str | None = None,
                 anim_joints: list[str] | None = None) -> tuple[UsdSkel.Skeleton, UsdSkel.Animation]:
    """A ``SkelRoot`` at ``root`` holding ``Skeleton`` ``Skel`` and ``SkelAnimation`` ``Anim``.

    ``joints``: joint paths (``a``, ``a/b``); ``offsets``: each joint's translation from its parent
    at rest (rotations none); ``poses``: time code -> per joint ``(axis, degrees)`` rotations;
    ``blend_shapes`` / ``blend_weights`` (time code -> weights): the animation's blend-shape
    channels. The animation is bound on the skeleton, or on the prim ``bind_anim_on`` (an ancestor
    whose ``skel:animationSource`` the skeleton inherits). ``anim_joints``: the joint names the
    animation animates (default: ``joints``)."""
    UsdSkel.Root.Define(stage, root)
    skel = UsdSkel.Skeleton.Define(stage, f"{root}/Skel")
    skel.CreateJointsAttr(joints)
    rest, world = [], {}
    for j, off in zip(joints, offsets):
        local = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*map(float, off)))
        rest.append(local)
        parent = j.rsplit("/", 1)[0] if "/" in j else None
        world[j] = local * world[parent] if parent else local
    skel.CreateRestTransformsAttr(rest)
    skel.CreateBindTransformsAttr([world[j] for j in joints])
    anim = UsdSkel.Animation.Define(stage, f"{root}/Anim")
    anim.CreateJointsAttr(anim_joints or joints)
    n = len(anim_joints or joints)
    anim.CreateTranslationsAttr([Gf.Vec3f(*map(float, o)) for o in offsets[:n]])
    anim.CreateScalesAttr([Gf.Vec3h(1, 1, 1)] * n)
    rot = anim.CreateRotationsAttr()
    for t, pose in poses.items():
        rot.Set(Vt.QuatfArray([_quat(ax, deg) for ax, deg in pose[:n]]), Usd.TimeCode(t))
    if blend_shapes:
        anim.CreateBlendShapesAttr(blend_shapes)
        bw = anim.CreateBlendShapeWeightsAttr()
        for t, w in (blend_weights or {}).items():
            bw.Set(Vt.FloatArray(list(map(float, w))), Usd.TimeCode(t))
    host = stage.GetPrimAtPath(bind_anim_on) if bind_anim_on else skel.GetPrim()
    UsdSkel.BindingAPI.Apply(host).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    return skel, anim


def usd_skinning(prim) -> tuple[UsdSkel.SkeletonQuery, UsdSkel.SkinningQuery]:
    """usd-core's own queries of the skinned mesh ``prim`` (the peer the tests and the skinning
    sweep compare with): its skeleton's ``SkeletonQuery`` and its ``SkinningQuery``."""
    cache = UsdSkel.Cache()
    root = UsdSkel.Root.Find(prim)
    cache.Populate(root, Usd.TraverseInstanceProxies())
    for binding in cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies()):
        for target in binding.GetSkinningTargets():
            if target.GetPrim() == prim:
                return cache.GetSkelQuery(binding.GetSkeleton()), target
    raise ValueError(f"{prim.GetPath()} is not skinned")


def bar_points(length: float, segments: int, half: float, origin=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, list[int], list[int]]:
    """A closed square bar along +x from ``origin``, ``length`` long, ``2 half`` thick, in
    ``segments`` rings: (points ``[4 (segments + 1), 3]``, face counts, face indices)."""
    xs = np.linspace(0.0, length, segments + 1)
    ring = [(-half, -half), (half, -half), (half, half), (-half, half)]
    pts = np.array([(origin[0] + x, origin[1] + y, origin[2] + z) for x in xs for y, z in ring], np.float64)
    counts, idx = [], []
    for i in range(segments):
        for k in range(4):
            a, b = i * 4 + k, i * 4 + (k + 1) % 4
            counts.append(4)
            idx += [a, a + 4, b + 4, b]
    last = segments * 4
    counts += [4, 4]
    idx += [0, 3, 2, 1, last, last + 1, last + 2, last + 3]
    return pts, counts, idx


def add_skinned_bar(stage: Usd.Stage, path: str, skel_path: str | None, pts: np.ndarray, counts, idx, indices, weights, per_point: int,
                    *, method: str | None = None, constant: bool = False, joints: list[str] | None = None,
                    geom_bind: Gf.Matrix4d | None = None) -> UsdGeom.Mesh:
    """A mesh bound with ``SkelBindingAPI``: ``skel:skeleton`` (None: unbound), joint indices and
    weights (``per_point`` influences a point, or one set for the whole mesh when ``constant``),
    ``skel:skinningMethod``, ``skel:joints`` and ``geomBindTransform`` when given."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts, np.float32)))
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(idx)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    if skel_path is not None:
        binding.CreateSkeletonRel().SetTargets([Sdf.Path(skel_path)])
    binding.CreateJointIndicesPrimvar(constant, per_point).Set(Vt.IntArray(list(map(int, indices))))
    binding.CreateJointWeightsPrimvar(constant, per_point).Set(Vt.FloatArray(list(map(float, weights))))
    binding.CreateGeomBindTransformAttr(geom_bind if geom_bind is not None else Gf.Matrix4d(1.0))
    if method is not None:
        binding.CreateSkinningMethodAttr(method)
    if joints is not None:
        binding.CreateJointsAttr(joints)
    return mesh


def elbow_weights(pts: np.ndarray, x0: float, lo: float = 0.5, hi: float = 1.5) -> tuple[list[int], list[float]]:
    """Two influences a point: joint 0 (the upper arm) and joint 1 (the forearm), the forearm's
    weight rising from 0 at ``x0 + lo`` to 1 at ``x0 + hi``."""
    idx, w = [], []
    for x in pts[:, 0] - x0:
        f = float(np.clip((x - lo) / (hi - lo), 0.0, 1.0))
        idx += [0, 1]
        w += [1.0 - f, f]
    return idx, w


def arm_stage(path: str | None = None, *, method: str | None = None, bend: float = 90.0, twist: float = 0.0,
              four_joints: bool = False, blend: bool = False, inherited: bool = False, skeleton: bool = True,
              bad_index: bool = False, nan_weight: bool = False, anim_joints: list[str] | None = None) -> Usd.Stage:
    """A ground (±4) under a 1 x 1 rect light 4 up, and an arm 2 long lying 1 above it along +x from
    x = -1: a skeleton of two joints (shoulder at x = -1, elbow at x = 0) whose animation bends the
    elbow by ``bend`` degrees about +z at time code 10 (0 at time 0) and twists it by ``twist``
    about +x. Variants: ``four_joints`` (a chain of four joints, every point weighted over all four),
    ``blend`` (a blend shape ``bulge`` with an inbetween at 0.5, weight 1 at time 10),
    ``inherited`` (the animation bound on the SkelRoot's parent), ``skeleton`` False (no
    ``skel:skeleton``), ``bad_index`` (a joint index of 7), ``nan_weight`` (a NaN weight)."""
    stage = make_stage(path=path)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(10)
    add_quad(stage, "/World/Ground", (0, 0, 0), 4)
    add_rect_light(stage, "/World/Light", (0, 0, 4), 1.0, 1.0)
    add_camera(stage, "/World/Cam", (0, -0.01, 9), (0, 0, 0))
    root = "/World/Char"
    UsdGeom.Xform.Define(stage, "/World/Rig") if inherited else None
    if inherited:
        root = "/World/Rig/Char"
    n = 4 if four_joints else 2
    joints = ["j0", "j0/j1", "j0/j1/j2", "j0/j1/j2/j3"][:n]
    step = 2.0 / n if four_joints else 1.0
    offsets = [(-1.0, 0.0, 1.0)] + [(step, 0.0, 0.0)] * (n - 1)
    bent = [((0, 0, 1), 0.0)] + [((0, 0, 1), bend / (n - 1))] * (n - 1)
    if twist:
        bent = [((0, 0, 1), 0.0)] + [((1, 0, 0), twist)] * (n - 1)
    poses = {0: [((0, 0, 1), 0.0)] * n, 10: bent}
    shapes = ["bulge"] if blend else None
    add_skeleton(stage, root, joints, offsets, poses, blend_shapes=shapes, blend_weights={0: [0.0], 10: [1.0]} if blend else None,
                 bind_anim_on="/World/Rig" if inherited else None, anim_joints=anim_joints)
    if inherited:  # the animation source is inherited from /World/Rig: the skeleton binds none of its own
        stage.GetPrimAtPath(f"{root}/Skel").RemoveAPI(UsdSkel.BindingAPI)
    pts, counts, idx = bar_points(2.0, 16, 0.15, (-1.0, 0.0, 1.0))
    if four_joints:
        ji, jw = [], []
        for x in pts[:, 0] + 1.0:
            c = np.array([abs(x - (k + 0.5) * step) for k in range(4)])
            w = np.exp(-(c / step) ** 2)
            w /= w.sum()
            ji += [0, 1, 2, 3]
            jw += list(map(float, w))
        per = 4
    else:
        ji, jw = elbow_weights(pts, -1.0, 0.8, 1.2)
        per = 2
    if bad_index:
        ji[5] = 7
    if nan_weight:
        jw[3] = float("nan")
    mesh = add_skinned_bar(stage, f"{root}/Arm", f"{root}/Skel" if skeleton else None, pts, counts, idx, ji, jw, per, method=method)
    if blend:
        shape = UsdSkel.BlendShape.Define(stage, f"{root}/Arm/bulge")
        top = np.where(pts[:, 2] > 1.0)[0]
        shape.CreatePointIndicesAttr(Vt.IntArray(list(map(int, top))))
        shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0.4)] * len(top)))
        half = shape.CreateInbetween("half")
        half.SetWeight(0.5)
        half.SetOffsets(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0.1)] * len(top)))
        b = UsdSkel.BindingAPI(mesh.GetPrim())
        b.CreateBlendShapesAttr(["bulge"])
        b.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    return stage
