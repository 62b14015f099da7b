"""Where float32 precision ends, and that every technique's answer holds up to there: a stage far
from the world origin, a light far from its receivers, a scene a billionth of a unit wide, and a
lamp just above the ceiling of a room the camera stands in."""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.lightspace.view import LIGHT_REACH, frame_extent_of_bounds
from wsoft.stages.builders import add_box, add_camera, add_quad, add_rect_light, add_sphere_light, make_stage

W, H = 48, 36


def _base(offset=(0.0, 0.0, 0.0), scale: float = 1.0, sphere_at: float | None = None):
    """The corpus's base (a ±5 ground, a ±1 occluder at z = 1, a 1 x 1 rect light at z = 3, a camera
    at (0, -6, 5)) moved by ``offset`` and scaled by ``scale``; ``sphere_at``: a sphere light of the
    sun's angular radius (0.53°) at that height instead of the rect light."""
    st = make_stage()
    o = np.asarray(offset, np.float64)

    def at(p):
        return tuple(o + scale * np.asarray(p, np.float64))

    add_quad(st, "/World/Ground", at((0, 0, 0)), 5 * scale)
    add_quad(st, "/World/Occluder", at((0, 0, 1)), 1 * scale)
    if sphere_at is None:
        add_rect_light(st, "/World/Light", at((0, 0, 3)), scale, scale)
    else:
        add_sphere_light(st, "/World/Light", at((0, 0, sphere_at)), scale * sphere_at * np.tan(np.radians(0.53)))
    add_camera(st, "/World/Cam", at((0, -6, 5)), at((0, 0, 0)), clip=(0.01 * scale, 1000.0 * scale))
    return st


def _scene(st, tmp_path, name: str):
    path = tmp_path / f"{name}.usda"
    st.GetRootLayer().Export(str(path))
    return wsoft.load_scene(str(path))


def _params(technique: str) -> dict:
    from wsoft.techniques import get_technique

    cls = get_technique(technique)
    p = {**cls.quick_params, **({cls.size_param: 256} if cls.size_param else {})}
    return {**p, "samples": 64} if technique == "reference" else p


def _mean_v(scene, technique: str) -> tuple[float, object]:
    f = wsoft.render(scene, technique, width=W, height=H, device="cpu", **_params(technique))
    return float(f.V[f["A"] > 0].mean()), f


RAY_TRACED = ("reference", "dcs", "izb", "pwedge")


@pytest.mark.parametrize("offset", [(1e6, 1e6, 0.0), (0.0, 0.0, 1e6)], ids=["xy", "z"])
def test_far_from_the_origin_every_ray_traced_technique_keeps_its_shadow(tmp_path, offset):
    """A million units from the origin a fixed ray offset steps over the occluder (V 1.000); the
    render works in a frame centred on what the camera sees, so the shadow is the base's."""
    near = _scene(_base(), tmp_path, "near")
    far = _scene(_base(offset), tmp_path, "far")
    for t in RAY_TRACED:
        v0, _ = _mean_v(near, t)
        v1, f = _mean_v(far, t)
        assert abs(v1 - v0) < 0.005, (t, v0, v1)
    assert f.stats["counters"]["frame"]["local_origin"] is not None
    cov = f["A"] > 0  # P is in world space again
    assert np.all(np.abs(f["P.Z"][cov] - offset[2]) <= 1.5) and abs(float(np.median(f["P.X"][cov])) - offset[0]) < 6
    assert not [w for w in f.stats["warnings"] if "float32" in w]


def test_near_the_origin_the_render_stays_in_world_space(tmp_path):
    _, f = _mean_v(_scene(_base(), tmp_path, "near"), "hard")
    assert "local_origin" not in f.stats["counters"]["frame"]


def test_past_float32_precision_a_render_says_so(tmp_path):
    """At 1e8 float32 points are 8 units apart: the loaded geometry itself is quantised."""
    _, f = _mean_v(_scene(_base((1e8, 0.0, 0.0)), tmp_path, "farther"), "hard")
    assert any("float32 coordinates there are 8 apart" in w for w in f.stats["warnings"]), f.stats["warnings"]


def test_frame_extent_stops_following_a_far_light():
    from wsoft.scene.types import LIGHT_SPHERE, Light

    lo, hi = np.array([-5.0, -5.0, 0.0]), np.array([5.0, 5.0, 1.0])
    light = lambda z: Light(path="/L", kind=LIGHT_SPHERE, position=np.array([0.0, 0.0, z]), frame=np.eye(3), radius=1.0)  # noqa: E731
    d = float(np.linalg.norm(hi - lo))
    assert frame_extent_of_bounds(lo, hi, light(3.0)) == pytest.approx(float(np.linalg.norm([10, 10, 3])))
    cap = frame_extent_of_bounds(lo, hi, light(1e5))
    assert cap == frame_extent_of_bounds(lo, hi, light(1e7)) < (2 * LIGHT_REACH + 1) * d


@pytest.mark.parametrize("technique", ["reference", "hard", "pcss", "vsm", "essm", "ssm"])
def test_a_far_light_keeps_its_shadow(tmp_path, technique):
    """A sun-sized sphere light 10,000 units up casts the shadow it casts from 100 up: biases and
    ray offsets no longer grow with the light's distance, and the depth range is fitted to the
    casters (the reference: 0.959 at both; hard, pcss, ssm gave 1.000, vsm 1.000, essm 0.890)."""
    v100, _ = _mean_v(_scene(_base(sphere_at=100.0), tmp_path, "light100"), technique)
    v1e4, f = _mean_v(_scene(_base(sphere_at=1e4), tmp_path, "light1e4"), technique)
    assert abs(v1e4 - v100) < 0.006 and v1e4 < 0.97, (v100, v1e4)
    if technique != "reference":
        assert not [w for w in f.stats["warnings"] if "lose precision" in w]


def test_a_light_past_float32_depth_precision_says_so(tmp_path):
    _, f = _mean_v(_scene(_base(sphere_at=1e5), tmp_path, "light1e5"), "esm")
    assert any("lose precision" in w and "/World/Light" in w for w in f.stats["warnings"]), f.stats["warnings"]


@pytest.mark.parametrize("technique", ["essm", "vssm"])
def test_a_tiny_scene_keeps_its_shadow(tmp_path, technique):
    """The base a ten-billionth of its size: the depth-range floor is relative (essm gave 1.000)."""
    v1, _ = _mean_v(_scene(_base(), tmp_path, "unit"), technique)
    v2, f = _mean_v(_scene(_base(scale=1e-10), tmp_path, "tiny"), technique)
    assert abs(v2 - v1) < 0.005, (v1, v2)
    assert not f.stats["warnings"]


@pytest.mark.parametrize("technique", ["reference", "hard"])
def test_a_scene_1e_13_of_the_base_keeps_its_shadow(tmp_path, technique):
    """Triangles 2e-13 across: their normals are found from their corners (Warp's hit normal
    underflows to zero there and the occluder's pixels went dark: mean V 0.853)."""
    v1, _ = _mean_v(_scene(_base(), tmp_path, "unit"), technique)
    v2, f = _mean_v(_scene(_base(scale=1e-13), tmp_path, "tiny"), technique)
    assert abs(v2 - v1) < 0.002, (v1, v2)
    assert not f.stats["warnings"]


def test_a_scene_smaller_than_verified_says_so(tmp_path):
    _, f = _mean_v(_scene(_base(scale=1e-14), tmp_path, "tinier"), "hard")
    assert any("not verified" in w for w in f.stats["warnings"]), f.stats["warnings"]


def _room(tmp_path):
    """The base inside a closed, double-sided room (±2, z -0.5 to 2.5) whose ceiling lies half a
    unit below the rect light; the camera stands inside. Every receiver it sees is in shadow."""
    from pxr import UsdGeom

    st = _base()
    st.RemovePrim("/World/Cam")
    room = add_box(st, "/World/Room", (-2, -2, -0.5), (2, 2, 2.5))
    UsdGeom.Mesh(room.GetPrim()).CreateDoubleSidedAttr(True)
    add_camera(st, "/World/Cam", (0, -1.5, 1), (0, 0, 0))
    return _scene(st, tmp_path, "room")


@pytest.mark.parametrize("technique", ["pcss", "ssm", "vssm", "vsm", "hard"])
def test_a_ceiling_just_below_the_lamp_shadows_the_whole_room(tmp_path, technique):
    """The ceiling's vertices lie far outside the light view's window, its interior covers it:
    a soft view grows for casters crossing its edges (pcss gave mean V 0.39, ssm 0.41, vssm 0.41)."""
    v, f = _mean_v(_room(tmp_path), technique)
    assert v <= 0.001, v
    if technique != "hard":
        grown = [c.get("grown_for_casters", 0) for k, c in f.stats["counters"]["passes"].items() if k.startswith("fit_light_view")]
        assert max(grown) >= 1
