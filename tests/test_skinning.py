"""UsdSkel skinning (``wsoft.scene.usd_skel``, ``wsoft.scene.skinning``): the loaded points against
usd-core's own ``ComputeSkinnedPoints`` and ``BakeSkinning``, on every case of
``wsoft.stages.skel.arm_stage``; the posed arm's shadow; what cannot be evaluated."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import UsdGeom, UsdSkel

import wsoft
from wsoft.errors import SceneError
from wsoft.scene.usd import load_scene
from wsoft.stages.skel import arm_stage, usd_skinning

CASES = {
    "linear": {},
    "dual_quaternion": {"method": "dualQuaternion"},
    "four_joints": {"four_joints": True},
    "four_joints_dq": {"four_joints": True, "method": "dualQuaternion"},
    "twist_dq": {"twist": 150.0, "method": "dualQuaternion"},
    "blend_shape": {"blend": True},
    "inherited_animation": {"inherited": True},
}


def _arm_prim(stage):
    return next(p for p in stage.Traverse() if p.GetName() == "Arm")


def _usd_points(stage, t: float) -> np.ndarray:
    """The arm's world points as usd-core poses them: blend shapes, then ComputeSkinnedPoints, in the
    skeleton's world frame."""
    prim = _arm_prim(stage)
    query, target = usd_skinning(prim)
    pts = UsdGeom.Mesh(prim).GetPointsAttr().Get(t)
    if target.HasBlendShapes():
        bsq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
        w = query.GetAnimQuery().ComputeBlendShapeWeights(t)
        sw, bi, si = bsq.ComputeSubShapeWeights(w)
        bsq.ComputeDeformedPoints(sw, bi, si, bsq.ComputeBlendShapePointIndices(), bsq.ComputeSubShapePointOffsets(), pts)
    assert target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(t), pts, t)
    world = np.array(UsdGeom.XformCache(t).GetLocalToWorldTransform(query.GetSkeleton().GetPrim())).T
    p = np.asarray(pts, np.float64)
    return p @ world[:3, :3].T + world[:3, 3]


def _loaded_points(stage, t: float) -> np.ndarray:
    scene = load_scene(stage, time=t)
    i = next(k for k, name in enumerate(scene.prims) if name.endswith("/Arm"))
    first, count = scene.prim_points[i]
    return scene.points[first:first + count].astype(np.float64), scene


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("t", [0.0, 4.0, 10.0])
def test_points_equal_usd_skel(case, t):
    stage = arm_stage(**CASES[case])
    got, scene = _loaded_points(stage, t)
    want = _usd_points(stage, t)
    assert np.abs(got - want).max() < 1e-5
    assert not [w for w in scene.warnings if "Arm" in w]


def test_bake_skinning_agrees():
    """usd-core's BakeSkinning writes the posed points into the stage: the same points wsoft poses."""
    for kw in ({}, {"method": "dualQuaternion"}, {"blend": True}):
        stage = arm_stage(**kw)
        got = {t: _loaded_points(stage, t)[0] for t in (0.0, 10.0)}
        baked = arm_stage(**kw)
        assert UsdSkel.BakeSkinning(baked.Traverse())
        prim = _arm_prim(baked)
        for t, pts in got.items():
            local = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(t), np.float64)
            m = np.array(UsdGeom.XformCache(t).GetLocalToWorldTransform(prim)).T
            assert np.abs(local @ m[:3, :3].T + m[:3, 3] - pts).max() < 1e-4


def test_the_pose_moves_the_arm():
    """The interesting case happened: at time 10 the forearm's tip has left the bind pose's."""
    bind, _ = _loaded_points(arm_stage(), 0.0)
    bent, _ = _loaded_points(arm_stage(), 10.0)
    assert np.abs(bent - bind).max() > 0.9
    lin, _ = _loaded_points(arm_stage(twist=150.0), 10.0)
    dq, _ = _loaded_points(arm_stage(twist=150.0, method="dualQuaternion"), 10.0)
    # at the elbow linear blending collapses the twisted bar toward its axis; dual quaternions keep its width
    mid = np.abs(np.arange(len(lin)) // 4 - 8) <= 0
    r_lin = np.linalg.norm(lin[mid][:, 1:] - lin[mid][:, 1:].mean(0), axis=1).min()
    r_dq = np.linalg.norm(dq[mid][:, 1:] - dq[mid][:, 1:].mean(0), axis=1).min()
    assert r_lin < 0.6 * r_dq


def test_skinned_mesh_is_a_dynamic_caster():
    _, scene = _loaded_points(arm_stage(), 5.0)
    i = next(k for k, name in enumerate(scene.prims) if name.endswith("/Arm"))
    assert scene.tri_dynamic[scene.tri_prim == i].all()


def test_posed_shadow_matches_the_baked_stage(tmp_path):
    """The reference's shadow of the bent arm equals the shadow of the same triangles baked by
    usd-core (a static mesh at the posed points)."""
    stage = arm_stage(str(tmp_path / "arm.usda"))
    stage.GetRootLayer().Save()
    baked = arm_stage(str(tmp_path / "baked.usda"))
    assert UsdSkel.BakeSkinning(baked.Traverse())
    baked.GetRootLayer().Save()
    kw = {"width": 64, "height": 48, "device": "cpu", "samples": 16}
    a = wsoft.render(wsoft.load_scene(str(tmp_path / "arm.usda"), time=10.0), "reference", **kw)
    b = wsoft.render(wsoft.load_scene(str(tmp_path / "baked.usda"), time=10.0), "reference", **kw)
    bind = wsoft.render(wsoft.load_scene(str(tmp_path / "arm.usda"), time=0.0), "reference", **kw)
    assert np.abs(a.V - b.V).max() < 1e-6
    assert np.abs(a.V - bind.V).mean() > 0.01  # the pose moved the shadow


def test_unbound_mesh_is_said(tmp_path):
    scene = load_scene(arm_stage(skeleton=False), time=10.0)
    assert any("/Arm" in w and "no Skeleton deforms it" in w for w in scene.warnings)


@pytest.mark.parametrize("kw, attr", [({"bad_index": True}, "primvars:skel:jointIndices[5] = 7"),
                                      ({"nan_weight": True}, "primvars:skel:jointWeights[3]")])
def test_bad_influences_are_errors(kw, attr):
    with pytest.raises(SceneError, match=r"/World/Char/Arm") as e:
        load_scene(arm_stage(**kw), time=10.0)
    assert attr in str(e.value)


def test_animation_of_other_joints_is_said():
    scene = load_scene(arm_stage(anim_joints=["x", "y"]), time=10.0)
    assert any("animates none of its joints" in w and "/World/Char/Skel" in w for w in scene.warnings)


def test_influences_are_read_once_while_the_stage_is_unchanged():
    """A sequence's frames read the joint influences once; an edit of the stage reads them again."""
    from pxr import Vt

    from wsoft.scene.usd_skel import influence_cache

    stage = arm_stage()
    load_scene(stage, time=0.0)
    cache = influence_cache(stage)
    hits = cache.hits
    load_scene(stage, time=5.0)
    assert cache.hits == hits + 1
    prim = _arm_prim(stage)
    w = UsdSkel.BindingAPI(prim).GetJointWeightsPrimvar()
    vals = list(w.Get())
    vals[0], vals[1] = 0.0, 1.0
    w.Set(Vt.FloatArray(vals))
    assert not cache.values
    got, _ = _loaded_points(stage, 10.0)
    assert np.abs(got - _usd_points(stage, 10.0)).max() < 1e-5


def test_plan_and_stats_say_what_was_skinned():
    """``wsoft plan`` names the skinned meshes and the posing time; a frame's stats carry ``skin``."""
    from wsoft.cli import run_captured

    rc, out, err = run_captured(["plan", "walker"])
    assert rc == 0, err
    assert "skinned meshes (UsdSkel" in out and ": 10," in out
    fr = wsoft.render(wsoft.load_scene("walker", time=12.0), "hard", width=48, height=36, device="cpu")
    assert fr.stats["scene"]["skinned_meshes"] == 10 and fr.stats["timings_ms"]["skin"] > 0
