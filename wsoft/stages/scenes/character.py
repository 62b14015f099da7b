"""``walker``: a skinned figure stepping in place and waving under a rect light, feet on the floor.

One ``SkelRoot`` holds a ``Skeleton`` of 12 joints (pelvis, spine, head, both shoulders and
elbows, both hips and knees) and a ``SkelAnimation`` of 48 frames at 24 per second: the legs swing
±25° out of phase (knees bending on the way forward), the right arm waves above the head, the left
swings against its leg. Every body part is a square bar mesh bound to the joint it hangs from
and, near a joint, smoothly to the next one (two influences a point, linear blend skinning); the
head carries a blend shape ``jaw`` (its lower front face opening by 6 cm, an inbetween at half
weight). The figure is 1.8 tall with the soles 2 mm above z = 0 at rest (a foot's contact shadow),
a 0.6 x 0.6 rect light 3.5 up and 1 to the side, a camera looking down at the feet.
"""

from __future__ import annotations

import math
import os

import numpy as np
from pxr import Gf, Usd, UsdSkel, Vt

from wsoft.stages.builders import add_camera, add_material, add_mesh, add_rect_light, make_stage, set_doc_string
from wsoft.stages.mesh import quad_mesh
from wsoft.stages.skel import _quat

FRAMES = (1, 48)
FPS = 24.0

# joint name -> (parent, rest offset from the parent)
JOINTS = {
    "pelvis": (None, (0.0, 0.0, 0.95)),
    "spine": ("pelvis", (0.0, 0.0, 0.25)),
    "head": ("spine", (0.0, 0.0, 0.42)),
    "l_shoulder": ("spine", (0.22, 0.0, 0.33)),
    "l_elbow": ("l_shoulder", (0.0, 0.0, -0.3)),
    "r_shoulder": ("spine", (-0.22, 0.0, 0.33)),
    "r_elbow": ("r_shoulder", (0.0, 0.0, -0.3)),
    "l_hip": ("pelvis", (0.1, 0.0, -0.05)),
    "l_knee": ("l_hip", (0.0, 0.0, -0.44)),
    "r_hip": ("pelvis", (-0.1, 0.0, -0.05)),
    "r_knee": ("r_hip", (0.0, 0.0, -0.44)),
    "l_ankle": ("l_knee", (0.0, 0.0, -0.448)),
}

# body parts: (mesh name, joint it hangs from, child joint it bends into (or None), from, to, half thickness)
PARTS = [
    ("Torso", "pelvis", "spine", (0.0, 0.0, 0.9), (0.0, 0.0, 1.55), 0.14),
    ("L_UpperArm", "l_shoulder", "l_elbow", (0.22, 0.0, 1.53), (0.22, 0.0, 1.23), 0.045),
    ("L_Forearm", "l_elbow", None, (0.22, 0.0, 1.23), (0.22, 0.0, 0.95), 0.04),
    ("R_UpperArm", "r_shoulder", "r_elbow", (-0.22, 0.0, 1.53), (-0.22, 0.0, 1.23), 0.045),
    ("R_Forearm", "r_elbow", None, (-0.22, 0.0, 1.23), (-0.22, 0.0, 0.95), 0.04),
    ("L_Thigh", "l_hip", "l_knee", (0.1, 0.0, 0.9), (0.1, 0.0, 0.46), 0.07),
    ("L_Shin", "l_knee", None, (0.1, 0.0, 0.46), (0.1, 0.0, 0.012), 0.055),
    ("R_Thigh", "r_hip", "r_knee", (-0.1, 0.0, 0.9), (-0.1, 0.0, 0.46), 0.07),
    ("R_Shin", "r_knee", None, (-0.1, 0.0, 0.46), (-0.1, 0.0, 0.012), 0.055),
]


def _paths() -> list[str]:
    """Joint paths (``pelvis/spine/head``) in :data:`JOINTS` order."""
    out = {}
    for name, (parent, _) in JOINTS.items():
        out[name] = f"{out[parent]}/{name}" if parent else name
    return list(out.values())


def _limb(a, b, half: float, rings: int) -> tuple[np.ndarray, list[int], list[int], np.ndarray]:
    """A closed square bar from ``a`` to ``b``: points, face counts, indices and each point's
    fraction along the bar."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    axis = (b - a) / np.linalg.norm(b - a)
    u = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    ts = np.linspace(0.0, 1.0, rings + 1)
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    pts = np.array([a + t * (b - a) + half * (cu * u + cv * v) for t in ts for cu, cv in corners])
    frac = np.repeat(ts, 4)
    counts, idx = [], []
    for i in range(rings):
        for k in range(4):
            p, q = i * 4 + k, i * 4 + (k + 1) % 4
            counts.append(4)
            idx += [p, q, q + 4, p + 4]
    last = rings * 4
    counts += [4, 4]
    idx += [0, 3, 2, 1, last, last + 1, last + 2, last + 3]
    return pts, counts, idx, frac


def _pose(t: float) -> list:
    """Per joint ``(axis, degrees)`` at frame fraction ``t`` (0..1, one step cycle is half of it)."""
    w = 2.0 * math.pi * 2.0 * t  # two step cycles over the sequence
    swing = 25.0 * math.sin(w)
    knee = lambda s: max(0.0, 35.0 * math.sin(s))  # noqa: E731  (bends on the way forward)
    wave = 150.0 + 20.0 * math.sin(4.0 * w)
    pose = {
        "pelvis": ((0, 0, 1), 6.0 * math.sin(w)),
        "spine": ((1, 0, 0), 3.0),
        "head": ((0, 0, 1), 10.0 * math.sin(w)),
        "l_shoulder": ((1, 0, 0), swing),
        "l_elbow": ((1, 0, 0), -15.0),
        "r_shoulder": ((0, 1, 0), wave),
        "r_elbow": ((0, 1, 0), 20.0 * math.sin(4.0 * w)),
        "l_hip": ((1, 0, 0), -swing),
        "l_knee": ((1, 0, 0), knee(w + math.pi)),
        "r_hip": ((1, 0, 0), swing),
        "r_knee": ((1, 0, 0), knee(w)),
        "l_ankle": ((1, 0, 0), 0.0),
    }
    return [pose[n] for n in JOINTS]


def _skeleton(stage) -> tuple[UsdSkel.Skeleton, UsdSkel.Animation]:
    names, paths = list(JOINTS), _paths()
    skel = UsdSkel.Skeleton.Define(stage, "/World/Walker/Skel")
    skel.CreateJointsAttr(paths)
    rest, world = [], {}
    for n in names:
        parent, off = JOINTS[n]
        local = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*off))
        rest.append(local)
        world[n] = local * world[parent] if parent else local
    skel.CreateRestTransformsAttr(rest)
    skel.CreateBindTransformsAttr([world[n] for n in names])
    anim = UsdSkel.Animation.Define(stage, "/World/Walker/Anim")
    anim.CreateJointsAttr(paths)
    anim.CreateScalesAttr([Gf.Vec3h(1, 1, 1)] * len(names))
    anim.CreateBlendShapesAttr(["jaw"])
    tr, rot, bw = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateBlendShapeWeightsAttr()
    f0, f1 = FRAMES
    for f in range(f0, f1 + 1):
        s = (f - f0) / (f1 - f0)
        bob = 0.015 * (1.0 - math.cos(2.0 * math.pi * 4.0 * s))  # the pelvis dips as the legs pass
        offsets = [np.asarray(JOINTS[n][1]) - (np.array([0.0, 0.0, bob]) if n == "pelvis" else 0.0) for n in names]
        tr.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, o)) for o in offsets]), Usd.TimeCode(f))
        rot.Set(Vt.QuatfArray([_quat(ax, deg) for ax, deg in _pose(s)]), Usd.TimeCode(f))
        bw.Set(Vt.FloatArray([0.5 + 0.5 * math.sin(2.0 * math.pi * 3.0 * s)]), Usd.TimeCode(f))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    return skel, anim


def _bind(mesh, skel_path: str, joint: int, child: int | None, frac: np.ndarray) -> None:
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel_path])
    w = np.clip((frac - 0.8) / 0.2, 0.0, 0.5) if child is not None else np.zeros_like(frac)
    idx = np.stack([np.full_like(frac, joint), np.full_like(frac, child if child is not None else joint)], 1).astype(int)
    wts = np.stack([1.0 - w, w], 1)
    binding.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray(idx.ravel().tolist()))
    binding.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray(wts.ravel().tolist()))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))


def scene_walker(out_dir: str) -> dict[str, object]:
    """The skinned figure of this module: ``walker.usda``."""
    path = os.path.join(out_dir, "walker.usda")
    stage = make_stage("Z", path)
    stage.SetStartTimeCode(FRAMES[0])
    stage.SetEndTimeCode(FRAMES[1])
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetFramesPerSecond(FPS)
    tris = 0
    ground = quad_mesh([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)])
    add_mesh(stage, "/World/Ground", ground, False, add_material(stage, "/World/Looks/Floor", (0.75, 0.75, 0.72)))
    tris += 2
    UsdSkel.Root.Define(stage, "/World/Walker")
    skel, _ = _skeleton(stage)
    names = list(JOINTS)
    skin = add_material(stage, "/World/Looks/Skin", (0.75, 0.55, 0.45))
    for name, joint, child, a, b, half in PARTS:
        pts, counts, idx, frac = _limb(a, b, half, 8)
        mesh = add_mesh(stage, f"/World/Walker/{name}", (pts, counts, idx), False, skin)
        _bind(mesh, str(skel.GetPath()), names.index(joint), names.index(child) if child else None, frac)
        tris += sum(c - 2 for c in counts)
    # the head: a box on the neck, a blend shape opening its jaw (its lower front corners move down and forward)
    pts, counts, idx, frac = _limb((0.0, 0.0, 1.58), (0.0, 0.0, 1.82), 0.1, 4)
    head = add_mesh(stage, "/World/Walker/Head", (pts, counts, idx), False, skin)
    _bind(head, str(skel.GetPath()), names.index("head"), None, frac)
    jaw = np.where((pts[:, 2] < 1.65) & (pts[:, 1] < 0.0))[0]
    shape = UsdSkel.BlendShape.Define(stage, "/World/Walker/Head/jaw")
    shape.CreatePointIndicesAttr(Vt.IntArray(jaw.tolist()))
    shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0.0, -0.03, -0.06)] * len(jaw)))
    shape.CreateInbetween("half").SetOffsets(Vt.Vec3fArray([Gf.Vec3f(0.0, -0.02, -0.025)] * len(jaw)))
    shape.GetInbetween("half").SetWeight(0.5)
    hb = UsdSkel.BindingAPI(head.GetPrim())
    hb.CreateBlendShapesAttr(["jaw"])
    hb.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    tris += sum(c - 2 for c in counts)
    add_rect_light(stage, "/World/Light", (1.0, -0.6, 3.5), 0.6, 0.6, intensity=30.0)
    add_camera(stage, "/World/Camera", (1.5, -2.6, 1.7), (0.0, 0.0, 0.75))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", __doc__.split("\n\n")[0].replace("``walker``: ", ""))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}
