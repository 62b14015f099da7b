"""Surfaces a hair's breadth apart: a plate just above the ground, an occluder just under the light.

The scene of both: a ground 12 units across at z = 0, a 1 x 1 occluder at z = 1, a 0.5 x 0.5 rect
light at (3, 0, 3) facing down, a camera looking straight down from z = 12.
"""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_rect_light, make_stage


def _stage(plate_gap: float | None = None, quad_gap: float | None = None):
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    add_quad(st, "/World/Occluder", (0, 0, 1), 0.5)
    add_rect_light(st, "/World/Light", (3, 0, 3), 0.5, 0.5)
    add_camera(st, "/World/Cam", (0, 0, 12), (0, 0, 0), up=(0, 1, 0))
    if plate_gap is not None:  # single-sided, facing down (the camera sees its back), beside the occluder's shadow
        z = plate_gap
        add_mesh(st, "/World/Plate", ([(0.5, -0.5, z), (0.5, 0.5, z), (1.5, 0.5, z), (1.5, -0.5, z)], [4], [0, 1, 2, 3]),
                 double_sided=False, minimal=True)
    if quad_gap is not None:  # 0.2 x 0.2, quad_gap below the light's plane
        z = 3.0 - quad_gap
        add_mesh(st, "/World/Quad", ([(2.9, -0.1, z), (3.1, -0.1, z), (3.1, 0.1, z), (2.9, 0.1, z)], [4], [0, 1, 2, 3]),
                 double_sided=True, minimal=True)
    return wsoft.load_scene(st)


def _under_plate(frame) -> np.ndarray:
    """The pixels whose ground point lies well inside the plate's footprint (x in (0.6, 1.4), |y| < 0.4),
    out of the occluder's shadow (x in (-2.25, -0.75))."""
    x, y = frame["P.X"], frame["P.Y"]
    return (frame["A"] > 0) & (x > 0.6) & (x < 1.4) & (np.abs(y) < 0.4)


@pytest.mark.parametrize("gap", [1e-4, 3e-4])
def test_a_plate_just_above_the_ground_keeps_the_ground_and_its_shadow(gap):
    """The eye ray meets the plate's back (culled) and goes on a few ulps past it, so it meets the
    ground 1e-4 below (not the background); the ground's shadow rays start a few ulps off it, so
    they meet the plate 3e-4 above (not jump it): the reference and the techniques that trace rays
    say the ground there is in full shadow."""
    s = _stage(plate_gap=gap)
    fr = wsoft.render(s, [("reference", {"samples": 16}), "dcs", "rtdenoise"], width=80, height=60)
    ref = fr["reference"]
    under = _under_plate(ref)
    assert under.sum() >= 12  # the ground is seen there (the plate's back is culled)
    assert np.all(np.abs(ref["P.Z"][under]) < 1e-6)
    for t in ("reference", "dcs"):
        assert fr[t].V[under].max() == 0.0, t
    assert fr["rtdenoise"].V[under].max() < 0.02  # its filter blends in a little of the lit ground beyond


def test_an_occluder_just_under_the_light_is_mapped():
    """A 0.2 x 0.2 quad 1e-6 below the light's plane lies nearer the light than a near plane of
    1e-4 of the frame: the light view's near plane sits before it (half its depth), so ``hard``,
    whose answer is the light centre's visibility, is in shadow everywhere (the quad hides the
    centre from every receiver), as a ray from each receiver to the light's centre says."""
    s = _stage(quad_gap=1e-6)
    fr = wsoft.render(s, "hard", width=40, height=30)
    covered = fr["A"] > 0
    assert covered.sum() > 100
    assert fr.V[covered].max() == 0.0


@pytest.mark.parametrize("gap", [0.05, 1e-6])
def test_a_caster_nearer_the_light_than_its_size_is_named_for_soft_shadow_maps(gap):
    """A soft shadow map of the light sees the quad from the light's centre across the map and only
    it over the occluder's umbra (``pcss`` gives V 0.6 there at 0.05, ``ssm`` V 1 everywhere at
    1e-6, the truth 0 and 0.84): the light view's fit says so; a hard shadow map (the centre's own
    visibility, which the quad decides) does not, nor the stage without the quad."""
    fr = wsoft.render(_stage(quad_gap=gap), ["pcss", "hard"], width=40, height=30)
    said = [w for w in fr["pcss"].stats["warnings"] if "nearer than its size" in w]
    assert len(said) == 1 and "/World/Light" in said[0] and "trace rays" in said[0]
    assert not any("nearer than its size" in w for w in fr["hard"].stats["warnings"])
    assert not any("nearer than its size" in w for w in wsoft.render(_stage(), "pcss", width=40, height=30).stats["warnings"])
