"""The idealised rasterizer of the rasterizer's bound (``wsoft.bench.raster_bound``) draws the map the real
rasterizer draws, and culls the same faces: the bound times the same work, done more cheaply."""

from __future__ import annotations

import numpy as np
import pytest

from wsoft.lightspace.fit import fit_light_view
from wsoft.lightspace.view import DEPTH_CLEAR


@pytest.mark.parametrize("scene_name, light", [("multi_light", "Sun"), ("city", "Sun"), ("box_plane", None)])
def test_bound_draws_the_real_rasterizers_map(scene_name, light):
    from wsoft.bench.harness import load
    from wsoft.bench.raster_bound import Bound, culled
    from wsoft.raster.depth_map import rasterize
    from wsoft.scene.device import upload_scene

    scene = load(scene_name)
    lt = scene.find_light(light) if light else scene.lights[0]
    ds, _ = scene.device_copy("cpu", upload_scene)
    lo, hi = scene.bounds
    view = fit_light_view(lt, np.zeros((0, 3)), lo, hi, 256)
    if view.persp:
        with pytest.raises(ValueError, match="orthographic"):
            Bound(ds, view, 2, 64)
        return
    real = rasterize(ds, view, alpha_tested=False).depth.numpy()
    b = Bound(ds, view, 2, 64)
    b.draw()
    ideal = b.depth()
    a, r = ideal < DEPTH_CLEAR, real < DEPTH_CLEAR
    assert r.mean() > 0.1
    # the same coverage but for texel centres on an edge (the two evaluate edges in different orders)
    assert ((a != r).sum()) <= 1e-3 * r.sum()
    both = a & r
    assert np.max(np.abs(ideal[both] - real[both]) / np.maximum(np.abs(real[both]), 1e-3)) < 1e-4
    b.fetch()
    assert b.texels.numpy().sum() >= both.sum()  # the boxes hold every covered texel
    if scene_name == "multi_light":
        assert culled(ds, view).sum() > 400  # closed boxes: their far faces are culled, as the real rasterizer does


def test_foundation_bound_row_and_report(tmp_path):
    """The sweep's ``raster_bound`` row on a small orthographic view, and its report section."""
    import wsoft.bench.foundation as fnd

    case = {"kind": "raster_bound", "scene": "multi_light", "light": "Sun", "size": 256, "device": "cpu"}
    row = fnd._raster_bound(case, {})
    assert row["coverage_mismatch"] <= 1e-3 * row["covered"] and row["covered"] > 1000
    assert 0 < row["small"] <= row["covering"] <= row["triangles"] and row["culled"] > 400
    for k in ("ray_ms", "real_ms", "draw_ms", "small_ms", "fetch_ms"):
        assert row[k] > 0
    assert len(row["real_ms_runs"]) == 9 and len(row["ray_ms_runs"]) == 9
    md = tmp_path / "foundation.md"
    machine = {"python": "3", "cpu": "x86_64", "threads": 2, "cores": 2}
    fnd.report([row | {"case": case, "machine": machine}], md, {"command": "wsoft bench foundation", "out_dir": str(tmp_path), "quick": False})
    text = md.read_text()
    assert "## A bound on the 15x target" in text
    assert "| multi_light | Sun | 256 | " in text and f"{row['ray_ms'] / 15:.1f}" in text
