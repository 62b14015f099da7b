"""The llvmpipe peer of the light depth map (``wsoft.bench.llvmpipe``): on small scenes its map is
wsoft's, texel by texel, within the 24-bit target's steps and the two rasterizers' edge rules; where
moderngl or an EGL context is missing, the peer and the foundation row say why."""

from __future__ import annotations

import os

import numpy as np
import pytest

from wsoft.lightspace.view import DEPTH_CLEAR

# The tolerance of "the same map": texels drawn in one map only, and texels whose nearest surface
# differs (more than SAME_SURFACE_STEPS steps of the 24-bit target apart), each at most this
# fraction of the texels; the others within 4 steps at the 99th percentile.
MAX_TEXEL_FRACTION = 2e-3
P99_STEPS = 4.0


def _peer_or_skip():
    from wsoft.bench import llvmpipe

    reason = llvmpipe.unavailable()
    if reason:
        pytest.skip(f"llvmpipe peer unavailable: {reason}")
    return llvmpipe


def _instanced_cutout():
    import sys

    sys.path.insert(0, os.path.dirname(__file__))
    from instancing_util import rot, split, xf
    from wsoft.scene.usd import load_scene
    from wsoft.usd_scenes import resolve

    placements = [(0, xf()), (0, xf(rot((0, 0, 1), 0.5), (0.6, 0.3, 0.4), (0.7, 0.7, 1))), (1, xf(t=(-0.8, 0.5, 0.3))),
                  (1, xf(rot((1, 0, 0), 0.3), (0.9, -0.7, 0.6), (-1, 1, 1)))]
    inst, _ = split(load_scene(resolve("cutout")), ["Fence", "Leaf"], placements)
    return inst


@pytest.mark.parametrize("which", ["cutout", "multi_light Sun", "instanced cutout"])
def test_the_peers_map_is_wsofts(which):
    """Perspective (a rect light) with an alpha-tested cutout, orthographic (a distant light), and
    instances (two prototypes, one a cutout, rotated, scaled and mirrored) drawn by instanced rendering."""
    llvmpipe = _peer_or_skip()
    from wsoft.bench.foundation_llvmpipe import _depth_pass_inputs
    from wsoft.bench.harness import load

    if which == "instanced cutout":
        scene = _instanced_cutout()
    else:
        scene = load(which.split()[0])
    light = scene.find_light(which.split()[1]) if which == "multi_light Sun" else scene.lights[0]
    case = {"width": 96, "height": 72, "size": 256, "device": "cpu"}
    ds, view, alpha, casting, pass_map = _depth_pass_inputs(case, scene, light)
    peer = llvmpipe.LlvmpipeDepthMap(ds, view, alpha_tested=alpha, triangles=casting)
    peer.draw()
    c = llvmpipe.compare(pass_map.depth.numpy(), peer)
    assert c["covered_wsoft"] > 0.05 * c["texels"]
    assert c["coverage_differs"] <= MAX_TEXEL_FRACTION, c
    assert c["surface_differs"] <= MAX_TEXEL_FRACTION, c
    assert c["p99_diff_in_steps"] <= P99_STEPS, c
    assert view.persp == (which != "multi_light Sun")
    if which != "multi_light Sun":
        # the alpha test happened: without it the fence's holes are drawn (nearer depths where the
        # ground showed through), in both rasterizers alike
        from wsoft.raster.depth_map import rasterize

        assert alpha
        opaque = llvmpipe.LlvmpipeDepthMap(ds, view, alpha_tested=False, triangles=casting)
        opaque.draw()
        full = rasterize(ds, view, alpha_tested=False).depth.numpy()
        o = llvmpipe.compare(full, opaque)
        holes = opaque.linear_depth() < peer.linear_depth() * (1 - 1e-3)
        assert holes.mean() > 0.01
        assert np.mean(holes & ~(full < pass_map.depth.numpy() * (1 - 1e-3))) <= MAX_TEXEL_FRACTION
        assert o["coverage_differs"] <= MAX_TEXEL_FRACTION and o["surface_differs"] <= MAX_TEXEL_FRACTION, o
        opaque.release()
    if which == "instanced cutout":
        assert peer.instances_drawn == 4 and pass_map.instances_drawn == 4
        assert sorted({n for _, _, n, _ in peer.draws}) == [1, 2]  # the soup once, each prototype instanced twice
    peer.release()


def test_depth_turns_back_into_linear_depth():
    """A window depth of the view's near and far planes reads back as those depths, 1 as empty."""
    from wsoft.bench.llvmpipe import LlvmpipeDepthMap
    from wsoft.lightspace.view import LightView

    for persp in (True, False):
        v = LightView("/L", persp, np.zeros(3), np.eye(3), (-1.0, 1.0, -1.0, 1.0), 0.5, 40.0, 2, 1)
        m = LlvmpipeDepthMap.__new__(LlvmpipeDepthMap)
        m.view, m.gl_near = v, v.near
        m.window_depth = lambda: np.array([[0.0, 1.0]], np.float32)
        z = m.linear_depth()
        assert z[0, 0] == pytest.approx(0.5, rel=1e-6) and z[0, 1] == DEPTH_CLEAR
        # the view-projection puts a point at depth 10 where linear_depth reads 10 back
        from wsoft.bench.llvmpipe import view_projection

        q = view_projection(v) @ np.array([0.3, -0.2, 10.0, 1.0])
        m.window_depth = lambda q=q: np.array([[0.5 * q[2] / q[3] + 0.5, 1.0]], np.float32)
        assert m.linear_depth()[0, 0] == pytest.approx(10.0, rel=1e-5)
        assert q[0] / q[3] == pytest.approx(0.03 if persp else 0.3) and q[1] / q[3] == pytest.approx(-0.02 if persp else -0.2)


def test_missing_moderngl_gives_the_reason(monkeypatch):
    """Without moderngl the peer says so (and how to install it), and the foundation row is skipped with that reason."""
    import sys

    from wsoft.bench import foundation_llvmpipe as foundation
    from wsoft.bench import llvmpipe

    monkeypatch.setitem(sys.modules, "moderngl", None)  # import moderngl raises ImportError
    monkeypatch.setattr(llvmpipe, "_CONTEXT", {})
    reason = llvmpipe.unavailable()
    assert reason is not None and reason.startswith("moderngl not installed") and "wsoft[peers]" in reason
    with pytest.raises(llvmpipe.PeerUnavailable, match="moderngl not installed"):
        llvmpipe.LlvmpipeDepthMap(None, None, alpha_tested=False)
    row = foundation._raster_llvmpipe({"kind": "raster_llvmpipe", "scene": "box_plane", "light": None, "size": 256, "width": 48, "height": 36,
                                       "rounds": 1, "device": "cpu"}, {})
    assert row["skipped"] == reason
    lines = foundation._llvmpipe_section([row | {"case": {"kind": "raster_llvmpipe"}}])
    assert any("skipped: moderngl not installed" in line for line in lines)


def test_no_egl_context_gives_the_reason(monkeypatch):
    """A moderngl whose EGL context cannot start (no libEGL, no EGL device): the reason names it."""
    import sys
    import types

    from wsoft.bench import llvmpipe

    def fail(**kw):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setitem(sys.modules, "moderngl", types.SimpleNamespace(create_standalone_context=fail))
    monkeypatch.setattr(llvmpipe, "_CONTEXT", {})
    reason = llvmpipe.unavailable()
    assert reason.startswith("no headless EGL context (libEGL.so.1: cannot open shared object file")


def test_a_second_thread_count_is_refused():
    """llvmpipe reads LP_NUM_THREADS once: a process asking for another count is told so."""
    llvmpipe = _peer_or_skip()
    n = llvmpipe.context_info()["threads"]
    assert "LP_NUM_THREADS" in llvmpipe.unavailable(n + 1)
    assert llvmpipe.unavailable(n) is None
    assert "llvmpipe" in llvmpipe.context_info()["renderer"]


def test_only_the_rows_asked_for_run(monkeypatch, tmp_path):
    """``python -m wsoft.bench.foundation --only KIND`` runs only that kind's missing rows, then reports every row held."""
    from wsoft.bench import foundation

    ran = []
    monkeypatch.setattr(foundation, "cases", lambda quick, devices: [{"kind": "a", "n": 1}, {"kind": "b", "n": 2}, {"kind": "b", "n": 3}])
    monkeypatch.setattr(foundation, "run_case", lambda case, ctx: ran.append(case["n"]) or {"n": case["n"]})
    reported = []
    monkeypatch.setattr(foundation, "report", lambda rows, md, ctx: reported.append(sorted(r["n"] for r in rows)))
    assert foundation.run_only(["b"], out_dir=str(tmp_path)) == 0
    assert ran == [2, 3] and reported == [[2, 3]]
    assert foundation.run_only(["a", "b"], out_dir=str(tmp_path)) == 0
    assert ran == [2, 3, 1] and reported[-1] == [1, 2, 3]  # the rows held are not run again
    assert foundation.run_only(["c"], out_dir=str(tmp_path)) == 2


def test_large_triangles_are_the_banded_passes():
    """The fill row's `large` set is what the CPU rasterizer draws in its banded pass for large triangles (its own
    count), but for far faces of closed surfaces, which it culls first (and llvmpipe draws)."""
    from wsoft.bench.foundation_llvmpipe import _depth_pass_inputs, _large_triangles
    from wsoft.bench.harness import load
    from wsoft.raster.depth_map import rasterize

    scene = load("contact")
    ds, view, alpha, _, _ = _depth_pass_inputs({"width": 96, "height": 72, "size": 512, "device": "cpu"}, scene, scene.lights[0])
    tris = np.arange(scene.triangle_count, dtype=np.int32)
    large = _large_triangles(ds, view, tris)
    assert 0 < large.sum() < 10
    assert rasterize(ds, view, alpha, triangles=tris[~large]).big_triangles == 0
    banded = culled = 0
    for t in tris[large]:
        m = rasterize(ds, view, alpha, triangles=np.array([t], np.int32))
        banded += m.big_triangles
        culled += m.big_triangles == 0 and not (m.depth.numpy() < DEPTH_CLEAR).any()
    assert banded >= 1 and banded + culled == large.sum()
