"""``hard`` against the reference with one sample at the light's centre."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path

import wsoft
from wsoft.techniques import TECHNIQUES


@pytest.mark.parametrize("file,light", [("box_plane.usda", None), ("contact.usda", None), ("multi_light.usda", "Rect"), ("multi_light.usda", "Disk"), ("multi_light.usda", "Sphere"), ("multi_light.usda", "Sun"), ("cutout.usda", None)])
def test_hard_matches_centre_sample_reference(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    kw = dict(width=160, height=120, device=device, light=light)
    hard = wsoft.render(scene, "hard", shadow_map_size=2048, **kw)
    ref = wsoft.render(scene, "reference", samples=1, jitter=False, **kw)
    cov = hard["A"] > 0
    v, r = hard.V[cov], ref.V[cov]
    assert set(np.unique(v)) <= {0.0, 1.0}
    assert (r == 0).sum() > 50  # there is a shadow to get right
    agree = np.mean(v == r)
    assert agree > 0.99, f"only {agree:.4f} of pixels agree"


def test_contact_shadow_reaches_the_contact(device):
    """Under the cube resting on the ground, the ground right next to it is in shadow."""
    scene = wsoft.load_scene(scene_path("contact.usda"))
    hard = wsoft.render(scene, "hard", width=160, height=120, device=device, shadow_map_size=2048)
    ref = wsoft.render(scene, "reference", width=160, height=120, device=device, samples=1, jitter=False)
    near_contact = (hard["A"] > 0) & (np.abs(hard["P.Y"]) < 0.02) & (ref.V == 0)
    assert near_contact.sum() > 10
    assert np.mean(hard.V[near_contact] == 0) > 0.97  # no light leaking under the contact


def test_bias_is_needed_and_default_is_enough(device):
    scene = wsoft.load_scene(scene_path("contact.usda"))
    kw = dict(width=120, height=90, device=device, shadow_map_size=1024)
    none = wsoft.render(scene, "hard", bias=0.0, slope_bias=0.0, **kw)
    dflt = wsoft.render(scene, "hard", **kw)
    ref = wsoft.render(scene, "reference", width=120, height=90, device=device, samples=1, jitter=False)
    cov = dflt["A"] > 0
    acne = np.mean((none.V == 0) & (ref.V == 1) & cov)
    fixed = np.mean((dflt.V == 0) & (ref.V == 1) & cov)
    assert acne > fixed  # without bias, lit surfaces shadow themselves somewhere


def test_conservative_parameter_runs_conservative_pass(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "hard", width=32, height=24, device=device, conservative=True)
    assert "light_depth_conservative[Light]@1024" in f.stats["passes"]


def test_unknown_parameter_lists_known():
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    with pytest.raises(wsoft.ParameterError, match="shadow_map_size, bias, slope_bias, receiver_bias, plane_slope_bias, conservative"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", sample=4)
    with pytest.raises(wsoft.ParameterError, match="techniques: " + ", ".join(sorted(TECHNIQUES))):
        wsoft.render(scene, "nope", width=8, height=8, device="cpu")
    with pytest.raises(wsoft.ParameterError, match="not a valid int"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", shadow_map_size="big")
