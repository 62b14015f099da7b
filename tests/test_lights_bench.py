"""``wsoft bench lights`` (``bench/lights.py``): its rows come from the registry, its cone-edge row
measures what it says, the report holds every section; the bundled dome stages as the sweep reads them."""

from __future__ import annotations

import math

import numpy as np
import pytest

import wsoft
from wsoft.bench import lights
from wsoft.scene.usd_dome import dome_brightest_direction


def test_the_dome_technique_rows_are_the_registrys():
    from wsoft.techniques import TECHNIQUES

    takes_dome = sorted(n for n, c in TECHNIQUES.items() if c.dome_refusal == "" and n != "reference")
    rows = lights.cases(quick=True, devices=["cpu"])
    for scene, _ in lights.DOME_SCENES:
        assert sorted(r["technique"] for r in rows if r["kind"] == "dome_technique" and r["scene"] == scene) == takes_dome
    assert {r["kind"] for r in rows} == {"cone_edge", "spot_cost", "dome_convergence", "dome_cap", "dome_technique"}
    assert sorted(r["technique"] for r in rows if r["kind"] == "spot_cost") == sorted(lights.SPOT_TECHS)


def test_the_cone_edge_row_finds_the_edge_within_a_pixel(tmp_path, monkeypatch):
    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path))
    row = lights.run_case({"kind": "cone_edge", "technique": "hard", "device": "cpu", "width": 64, "height": 48}, {})
    assert row["ground_pixels"] > 1500 and row["edge_radius"] == pytest.approx(3 * math.tan(math.radians(30)))
    assert row["max_edge_offset_px"] <= 1.0 and 0.5 < row["deg_per_px"] < 5.0


def test_dusk_streets_sun_comes_from_its_skys_brightest_texel():
    sc = wsoft.load_scene("dusk_street")
    kinds = {l.name: l.kind_name for l in sc.lights}
    assert kinds == {"Sky": "dome", "Sun": "distant", "Spot30": "sphere", "Spot60": "sphere"}
    sky, sun = sc.find_light("Sky"), sc.find_light("Sun")
    assert sky.dome.texture.shape == (64, 128, 3) and sun.angle_deg == pytest.approx(0.53)
    assert np.dot(dome_brightest_direction(sky), -sun.direction) > math.cos(math.radians(0.1))
    assert dome_brightest_direction(sky)[2] > 0.05  # the sun is above the horizon, low: dusk
    s30, s60 = sc.find_light("Spot30").shaping, sc.find_light("Spot60").shaping
    assert (s30.cone_deg, s60.cone_deg) == (30.0, 60.0) and s30.softness > 0.0 and s60.ies is not None and s30.ies is None


@pytest.mark.slow
def test_the_quick_sweep_writes_every_section(tmp_path, monkeypatch):
    from wsoft.bench.harness import run_sweep

    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path / "cache"))
    assert run_sweep("lights", quick=True, out_dir=str(tmp_path)) == 0
    md = (tmp_path / "lights-quick.md").read_text()
    for title in ("The cone's edge on a plane", "A 30° spot's cost", "The dome reference: convergence", "The textured dome", "Dome techniques"):
        assert f"## {title}" in md
    assert (tmp_path / "lights-quick-convergence.png").exists()
