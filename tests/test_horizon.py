"""The receiver's horizon: a point sees only the part of a light in front of its visible side's
tangent plane (the reference per light sample, every technique by the shared front fraction)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage

import wsoft


def _wall_under_light():
    """A double-sided wall in the plane x = 0 under a 2 x 2 rect light whose centre is 0.25 behind
    that plane: every wall point has 3/8 of the light in front of its tangent plane (exactly 6 of
    the 16 columns of the front-fraction grid, 3 of the reference's 8 strata columns) and the
    light's centre behind it."""
    st = make_stage()
    add_quad(st, "/World/Wall", (0, 0, 1), 1, normal_axis="y")  # in the plane y = 0 ...
    from pxr import Gf, UsdGeom

    UsdGeom.XformCommonAPI(st.GetPrimAtPath("/World/Wall")).SetRotate(Gf.Vec3f(0, 0, 90))  # ... turned into x = 0
    add_rect_light(st, "/World/L", (-0.25, 0, 3), 2, 2)
    add_camera(st, "/World/Cam", (3, 0, 1), (0, 0, 1))
    return wsoft.load_scene(st)


@pytest.mark.parametrize("technique,want", [("reference", 0.375), ("pcss", 0.375), ("pcf", 0.375), ("vsm", 0.375), ("hard", 0.0)])
def test_a_light_straddling_the_plane_counts_its_front_part(device, technique, want):
    scene = _wall_under_light()
    params = {"samples": 64} if technique == "reference" else {}
    f = wsoft.render(scene, technique, width=32, height=24, device=device, **params)
    wall = f["A"] > 0
    assert wall.sum() > 150
    assert np.abs(f["N.X"][wall] - 1.0).max() < 1e-5  # the camera sees the +x side
    assert np.allclose(f.V[wall], want, atol=1e-6), (technique, f.V[wall].min(), f.V[wall].max())
    if technique != "reference":
        c = f.stats["counters"]["passes"]["front_centre[L]" if technique == "hard" else "front_fraction[L]"]
        assert c["light_straddles" if technique != "hard" else "light_behind"] == wall.sum()


def test_front_fraction_is_exact_on_either_side(device):
    """Wholly in front: 1; wholly behind: 0 — from the light's bounds, without sampling."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_rect_light(st, "/World/Above", (0, 0, 2), 1, 1)
    add_camera(st, "/World/Cam", (0, -4, 3), (0, 0, 0))
    scene = wsoft.load_scene(st)
    f = wsoft.render(scene, "pcss", width=24, height=18, device=device)
    assert f.stats["counters"]["passes"]["front_fraction[Above]"] == {"light_behind": 0, "light_straddles": 0}


def test_a_nan_in_a_technique_is_counted_and_warned(monkeypatch):
    """Never hide a NaN: a technique whose visibility holds NaN gives a frame whose stats count it
    per channel and a NonFiniteWarning (an error everywhere else in the suite)."""
    import warp as wp

    from wsoft.errors import NonFiniteWarning
    from wsoft.pipeline import context

    def broken(vis, front):
        v = vis.numpy()
        v[::7] = np.nan
        return wp.array(v, dtype=float, device=vis.device)

    monkeypatch.setattr(context, "clip_to_front", broken)
    scene = _wall_under_light()
    with pytest.warns(NonFiniteWarning, match="V"):
        f = wsoft.render(scene, "pcss", width=16, height=12, device="cpu")
    assert f.stats["nonfinite"]["V"] > 0 and any("non-finite" in w for w in f.stats["warnings"])
