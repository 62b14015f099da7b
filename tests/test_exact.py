"""The closed-form answers of wsoft.metrics.exact against the ray-traced reference."""

from __future__ import annotations

import numpy as np

import wsoft
from conftest import scene_path
from wsoft.metrics.exact import CUTOUT, checker_exact, cutout_exact


def test_cutout_checkerboard_exact_matches_the_reference():
    """The checkerboard fence's exact visibility (the opaque cells' projections onto the light)
    agrees with 256 traced samples to their noise; the other parity (cells swapped) does not."""
    f = wsoft.render(wsoft.load_scene(scene_path("cutout.usda")), "reference", width=128, height=96, samples=256)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3) & (f["P.X"] < CUTOUT["x_max"])
    e = cutout_exact(f["P.X"], f["P.Y"])
    pen = ((e > 0.01) & (e < 0.99))[g]
    assert pen.sum() > 300
    err = np.abs(f.V - e)[g]
    assert err[pen].mean() < 0.01 and err.max() < 0.08
    c = CUTOUT
    swapped = checker_exact(f["P.X"], f["P.Y"], c["light_z"], c["occ_z"], c["occ_half"], c["light_half"], c["cells"], 1 - c["opaque_parity"])
    assert np.abs(f.V - swapped)[g][pen].mean() > 0.1
