"""A distant light's view holds every caster that can block part of its cone from a receiver
(``wsoft.lightspace.fit.distant_caster_depth``): the caster points within ``(z_r - z) tan a`` of the
receivers' window, and with ``caster_triangles`` the interiors of triangles whose corners all lie
outside (a huge wall far off); a caster far off that cannot shadow a receiver moves nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wsoft.lightspace.fit import clipped_depth_min, cone_planes, distant_caster_depth, fit_light_view
from wsoft.lightspace.stable import fit_stable_view
from wsoft.scene.types import LIGHT_DISTANT, Light

SQ = math.sqrt(0.75)


def _sun(angle: float = 8.0) -> Light:
    """A sun arriving from 30 degrees off the zenith on the -x side (it emits along (0.5, 0, -0.87))."""
    z = np.array([-0.5, 0.0, SQ])  # the light's +Z points back toward the sun
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return Light(path="/Sun", kind=LIGHT_DISTANT, position=np.zeros(3), frame=np.stack([x, np.cross(z, x), z], axis=1), angle_deg=angle)


def _ground(n: int = 41) -> np.ndarray:
    g = np.linspace(-5.0, 5.0, n)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


def _wall(half_width: float, x: float = -100.0, height: float = 160.0) -> np.ndarray:
    """The two triangles of a wall in the plane ``x`` (world corners [2, 3, 3])."""
    a, b, c, d = (x, -half_width, 0.0), (x, half_width, 0.0), (x, half_width, height), (x, -half_width, height)
    return np.array([[a, b, c], [a, c, d]], np.float64)


def _mesh(tris: np.ndarray):
    """World triangles ``[T, 3, 3]`` as (points, triangles into them), as Scene.caster_mesh gives them."""
    return tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3)


def _fit(light, casters_tris, stable=False, with_triangles=True, size=256):
    rec = _ground()
    pts = np.concatenate([rec, casters_tris.reshape(-1, 3)]) if len(casters_tris) else rec
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    kw = dict(casters=pts, caster_triangles=(lambda: _mesh(casters_tris)) if with_triangles else None)
    if stable:
        return fit_stable_view(light, rec, lo, hi, size, **kw)
    return fit_light_view(light, rec, lo, hi, size, **kw)


def test_clipping_finds_the_nearest_point_of_a_triangle_inside_a_region():
    """Against brute force: the smallest depth of a dense barycentric sampling of each triangle
    inside the region is never below the clipped answer and comes within the sampling's step."""
    rng = np.random.default_rng(3)
    planes = cone_planes((-1.0, 1.0, -1.0, 1.0), 5.0, 0.2)
    tris = rng.uniform(-6.0, 6.0, size=(300, 3, 3))
    got = clipped_depth_min(tris, planes)
    n = 120
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    w = 1.0 - u - v
    crossing = 0
    for k, t in enumerate(tris):
        p = u[:, None] * t[0] + v[:, None] * t[1] + w[:, None] * t[2]
        inside = np.all(p @ planes[:, :3].T + planes[:, 3] >= 0.0, axis=1)
        if not inside.any():
            assert got[k] == np.inf or got[k] > p[:, 2].min() - 1e-9  # a sliver the sampling missed
            continue
        best = p[inside, 2].min()
        step = 12.0 * math.sqrt(3.0) * 2.0 / n  # the sampling's spacing bounds how far it misses
        assert got[k] <= best + 1e-9 and got[k] >= best - step, k
        crossing += not np.all(np.all(t @ planes[:, :3].T + planes[:, 3] >= 0.0, axis=1))
    assert crossing > 20  # many triangles were clipped, not wholly inside


def test_a_huge_triangle_crossing_the_region_counts_through_its_interior():
    window = (-5.0, 5.0, -5.0, 5.0)
    tri = np.array([[[-1e4, -1e4, -50.0], [1e4, -1e4, -50.0], [0.0, 1e4, -50.0]]])  # corners far outside, at depth -50
    pts = tri.reshape(-1, 3)
    view = (np.zeros(3), np.eye(3))  # world space is the view's
    assert distant_caster_depth(pts, window, 0.0, 1.0, 0.05) == 0.0  # its corners alone: not in the region
    assert distant_caster_depth(pts, window, 0.0, 1.0, 0.05, _mesh(tri), *view) == pytest.approx(-50.0)
    # beside the region: a caster 60 units off the window at depth -50 blocks only within 0.05 * 51
    off = tri + np.array([0.0, 1e4 + 65.0, 0.0])
    assert distant_caster_depth(off.reshape(-1, 3), window, 0.0, 1.0, 0.05, _mesh(off), *view) == 0.0


@pytest.mark.parametrize("stable", [False, True], ids=["fitted", "stable"])
def test_the_view_holds_a_far_wall_that_blocks_part_of_the_cone(stable):
    """The wall of the ``sun_far_wall`` case: 185 upstream of the ground, outside the receivers'
    window; the view's depth range reaches it and the window grows by its reach."""
    light = _sun()
    bare = _fit(light, np.zeros((0, 3, 3)), stable)
    for half_width, with_triangles in ((8.0, False), (1e4, True)):
        v = _fit(light, _wall(half_width), stable, with_triangles)
        assert v.far > bare.far + 150.0, half_width  # the depth range starts at the wall's top
        grow = math.tan(math.radians(4.0)) * 150.0
        assert (v.window[1] - v.window[0]) > (bare.window[1] - bare.window[0]) + 2.0 * grow
    # the huge wall without its triangles: its corners are outside, nothing moves
    v = _fit(light, _wall(1e4), stable, with_triangles=False)
    assert v.window == bare.window and v.far == bare.far


@pytest.mark.parametrize("stable", [False, True], ids=["fitted", "stable"])
def test_a_far_caster_that_cannot_shadow_leaves_the_view_alone(stable):
    """A wall as far off but too low to reach the cone (its top at 30 degrees of elevation from the
    ground), and one beside the receivers' region, triangles given: the view is the bare one."""
    light = _sun()
    bare = _fit(light, np.zeros((0, 3, 3)), stable)
    low = _wall(1e4, height=40.0)
    aside = _wall(8.0) + np.array([0.0, 400.0, 0.0])
    for caster in (low, aside):
        v = _fit(light, caster, stable)
        assert v.window == bare.window and v.far == bare.far and np.allclose(v.origin, bare.origin)


def test_a_hard_sun_needs_no_growth_and_keeps_its_window():
    """A sun of angle 0: only casters in the receivers' prism count; the far wall (never in it) changes nothing."""
    light = _sun(0.0)
    bare = _fit(light, np.zeros((0, 3, 3)))
    v = _fit(light, _wall(1e4))
    assert v.window == bare.window and v.far == bare.far


def test_scene_caster_mesh_is_the_soup_and_each_instance_box():
    from wsoft.pipeline import load_stage

    scene = load_stage("box_plane")
    pts, tris = scene.caster_mesh()
    assert np.array_equal(pts[tris], scene.points[scene.triangles])
    inst = load_stage("plants", instancing="keep")
    assert inst.instanced
    pts, tris = inst.caster_mesh()
    n = inst.instances.count
    assert len(tris) == inst.triangle_count + 12 * n and len(pts) == len(inst.points) + 8 * n
    lo, hi = inst.instances.world_bounds
    boxes = pts[tris[inst.triangle_count:]].reshape(n, 36, 3)
    assert np.allclose(boxes.min(axis=1), lo, atol=1e-4) and np.allclose(boxes.max(axis=1), hi, atol=1e-4)
