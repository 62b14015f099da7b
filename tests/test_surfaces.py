"""Surface details: single-sided culling in the eye view, texture wrap modes, automatic camera."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import add_camera, add_quad, add_rect_light, make_stage

import wsoft
from wsoft.scene.device import upload_scene
from wsoft.scene.surfaces import Surfaces, sample_alpha
from wsoft.scene.types import WRAP_BLACK, WRAP_CLAMP, WRAP_MIRROR, WRAP_REPEAT, Material, Scene, Texture


def test_single_sided_back_face_is_culled_but_casts_shadow(device):
    """A single-sided roof facing the ground: the camera above sees through its back face to
    the ground, and the ground under it is still in its shadow (both sides cast shadows)."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 4)
    roof = add_quad(st, "/World/Roof", (0, 0, 1), 1, double_sided=False)
    roof.CreateOrientationAttr("leftHanded")  # now it faces -Z, toward the ground
    add_rect_light(st, "/World/L", (0, 0, 3), 0.2, 0.2)
    add_camera(st, "/World/Above", (0, -0.01, 6), (0, 0, 0))
    s = wsoft.load_scene(st)
    f = wsoft.render(s, "reference", width=48, height=48, device=device, samples=4)
    under = (f["A"] > 0) & (np.abs(f["P.X"]) < 0.5) & (np.abs(f["P.Y"]) < 0.5)
    assert under.sum() > 20
    assert np.all(np.abs(f["P.Z"][under]) < 1e-3)  # the camera sees the ground through the culled roof
    assert np.all(f.V[under] == 0)  # and the roof shadows it
    s.tri_double_sided[:] = True
    s.changed()
    f2 = wsoft.render(s, "hard", width=48, height=48, device=device)
    assert np.all(np.abs(f2["P.Z"][under] - 1) < 1e-3)  # double-sided, the roof is what the camera sees


@wp.kernel
def _sample_kernel(cut: Surfaces, st: wp.array[wp.vec2], out: wp.array[float]):
    i = wp.tid()
    out[i] = sample_alpha(cut, 0, st[i])


def _alpha_at(device, wrap, st):
    tex = np.array([[0.0, 1.0], [0.25, 0.5]], np.float32)  # row 0 = bottom (t near 0)
    scene = Scene(
        path="mem", points=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), triangles=np.array([[0, 1, 2]], np.int32),
        tri_prim=np.zeros(1, np.int32), tri_material=np.array([1], np.int32), tri_uv=np.zeros((1, 3, 2), np.float32),
        tri_double_sided=np.ones(1, bool), prims=["/T"], materials=[Material("d"), Material("m", opacity_threshold=0.5, texture=0)],
        textures=[Texture("t.png", tex, wrap, wrap)],
    )
    ds = upload_scene(scene, device)
    sts = wp.array(np.asarray(st, np.float32), dtype=wp.vec2, device=device)
    out = wp.empty(len(st), dtype=float, device=device)
    wp.launch(_sample_kernel, dim=len(st), inputs=[ds.cutouts, sts], outputs=[out], device=device)
    return out.numpy()


@pytest.mark.parametrize(
    "wrap,expected",
    [
        (WRAP_REPEAT, [0.0, 1.0, 0.25, 0.0]),
        (WRAP_MIRROR, [0.0, 1.0, 0.25, 1.0]),
        (WRAP_CLAMP, [0.0, 1.0, 0.25, 1.0]),
        (WRAP_BLACK, [0.0, 1.0, 0.25, 0.0]),
    ],
)
def test_wrap_modes(device, wrap, expected):
    # texel centres: (0.25, 0.25) -> [0,0]; (0.75, 0.25) -> [0,1]; (0.25, 0.75) -> [1,0]; (1.25, 0.25) wraps
    got = _alpha_at(device, wrap, [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (1.25, 0.25)])
    assert np.allclose(got, expected, atol=1e-6)


def test_automatic_camera_frames_the_scene(device):
    st = make_stage()
    add_quad(st, "/World/G", (10, 20, 0), 5)
    add_quad(st, "/World/O", (10, 20, 1), 1)
    add_rect_light(st, "/World/L", (10, 20, 3), 1, 1)
    s = wsoft.load_scene(st)
    assert s.cameras == []
    f = wsoft.render(s, "hard", width=64, height=48, device=device)
    assert f.stats["camera"] == "(automatic)"
    assert 0.2 < f["A"].mean() < 1.0 and f.V.min() == 0
