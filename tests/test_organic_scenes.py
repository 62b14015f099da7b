"""The organic paper-analog scenes (``wsoft.stages.scenes.organic``) load and are what their docs say."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path

import wsoft
from wsoft.scene.types import LIGHT_RECT

# scene -> (file, min triangles, max triangles, prim prefixes of the creatures touching the ground)
ORGANIC = {
    "ogre": ("ogre.usdc", 130_000, 140_000, ["/World/Ogre"]),
    "plants": ("plants.usdc", 130_000, 150_000, []),
    "dinosaurs": ("dinosaurs.usdc", 300_000, 420_000, ["/World/Dinosaurs/"]),
    "fig1_plant": ("fig1_plant.usdc", 20_000, 80_000, []),
    "fig8_tree": ("fig8_tree.usdc", 30_000, 120_000, []),
    "palm_dino": ("palm_dino.usdc", 40_000, 150_000, ["/World/Dino"]),
}

_CACHE: dict = {}


def _load(name: str):
    if name not in _CACHE:
        _CACHE[name] = wsoft.load_scene(scene_path(ORGANIC[name][0]))
    return _CACHE[name]


def _tri_mask(scene, prefixes) -> np.ndarray:
    hit = np.array([any(p == q or p.startswith(q) for q in prefixes) for p in scene.prims], bool)
    return hit[scene.tri_prim]


@pytest.mark.parametrize("name", list(ORGANIC))
def test_organic_scene(name):
    _file, lo, hi, creatures = ORGANIC[name]
    s = _load(name)
    assert s.up_axis == "Z" and s.meters_per_unit == 1.0
    assert lo <= s.triangle_count <= hi, s.triangle_count
    assert np.isfinite(s.points).all()
    assert any(c.path == "/World/Camera" for c in s.cameras)
    rects = [lt for lt in s.lights if lt.kind == LIGHT_RECT]  # s.lights: shadow-casting only
    assert rects, [lt.kind_name for lt in s.lights]
    for lt in rects:
        assert lt.direction[2] < -0.7  # faces down onto the scene
    ground = _tri_mask(s, ["/World/Ground"])
    assert ground.any() and not ground.all()
    gpts = s.points[np.unique(s.triangles[ground])]
    assert np.all(gpts[:, 2] == 0.0)
    occ = s.points[np.unique(s.triangles[~ground])]
    assert occ[:, 2].min() >= -1e-5  # nothing below the ground
    assert occ[:, 2].max() > 1.0  # and well above it
    for lt in rects:
        assert lt.position[2] > occ[:, 2].max()  # light above every occluder
    assert s.tri_dynamic is None or not s.tri_dynamic.any()  # all static
    if creatures:
        cm = _tri_mask(s, creatures)
        assert cm.any()
        cpts = s.points[np.unique(s.triangles[cm])]
        assert cpts[:, 2].min() <= 1e-3  # feet touch the ground: contact shadows
        assert cpts[:, 2].max() > 1.5


def test_dinosaurs_are_instances():
    s = _load("dinosaurs")
    dinos = sorted({p.split("/")[3] for p in s.prims if p.startswith("/World/Dinosaurs/")})
    assert 3 <= len(dinos) <= 4
    per = s.triangle_count // len(dinos)
    assert 90_000 <= per <= 110_000
