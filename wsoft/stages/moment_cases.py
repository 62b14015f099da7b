"""The stage that moment-based shadow maps exist for: occluders stacked at different depths, where
a kernel of a filtered map sees two or three of them at once and a bound on few moments lets
light through (``vsm``'s light bleeding), for ``tests/test_moments.py`` and the sweeps
(:func:`wsoft.metrics.leak.umbra_leak` measures it).

``stacked_plates``: three parallel slatted plates (louvres) under a small rect light (0.4 x 0.4 at
height 4) over a ground: at height 0.15 four slats along y (0.3 wide, 0.3 apart), at 1.2 five
slats along x (0.25 wide, 0.25 apart), at 2.4 three slats along y (0.2 wide, 0.4 apart, offset by
0.15). The lowest slats lie just above the ground, so a kernel that sees their depth and an upper
plate's edge has a large variance against a receiver only a little behind the mean: Chebyshev's
bound lights the ground in their umbra there. Slats rather than solid plates: a kernel is a few
texels wide, so only the umbra near an upper edge can leak, and slats give many edges; and the
camera (oblique, across the lowest slats) sees the ground under them. ``plates=2`` leaves the top
plate out, ``plates=1`` both upper ones (nothing stacks: what leaks then is the filter's own
softening of the lowest slats' edges, the baseline).

:func:`stage_file` writes it once as a ``.usda`` into ``$WSOFT_CACHE_DIR/stages`` (default
``~/.cache/wsoft/stages``; rewritten only when its text changes, so cached references stay valid)
for a sweep that names stages by path.
"""

from __future__ import annotations

import os

from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_rect_light, make_stage

#: each plate, lowest first: (height, slats, slat width, gap, half length, the axis slats run along, offset across them)
PLATES = ((0.15, 4, 0.3, 0.3, 1.0, "y", 0.0), (1.2, 5, 0.25, 0.25, 1.2, "x", 0.15), (2.4, 3, 0.2, 0.4, 1.2, "y", 0.0))
LIGHT_Z = 4.0
LIGHT_SIZE = 0.4


def slatted_plate(height: float, slats: int, width: float, gap: float, half_length: float, along: str, offset: float):
    """The mesh (points, counts, indices) of ``slats`` parallel horizontal strips at ``height``, each
    ``width`` wide and 2 ``half_length`` long along ``along`` (``x`` or ``y``), ``gap`` apart,
    centred on the vertical axis and shifted by ``offset`` across the strips."""
    pts, counts, idx = [], [], []
    span = slats * width + (slats - 1) * gap
    for i in range(slats):
        a = -0.5 * span + i * (width + gap) + offset
        b = a + width
        if along == "y":
            quad = [(a, -half_length, height), (b, -half_length, height), (b, half_length, height), (a, half_length, height)]
        else:
            quad = [(-half_length, a, height), (half_length, a, height), (half_length, b, height), (-half_length, b, height)]
        k = len(pts)
        pts += quad
        counts.append(4)
        idx += [k, k + 1, k + 2, k + 3]
    return pts, counts, idx


def stacked_plates(plates: int = 3):
    """The in-memory stage (module docstring): the ground, the lowest ``plates`` plates, the light, the camera."""
    if plates not in (1, 2, 3):
        raise ValueError(f"plates must be 1, 2 or 3, not {plates}")
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4.0)
    for j, plate in enumerate(PLATES[:plates]):
        add_mesh(st, f"/World/Plate{j}", slatted_plate(*plate), True, minimal=True)
    add_rect_light(st, "/World/Light", (0, 0, LIGHT_Z), LIGHT_SIZE, LIGHT_SIZE)
    add_camera(st, "/World/Cam", (-2.5, -0.3, 3.0), (0.0, 0.0, 0.0), focal=18)
    return st


def stage_file(plates: int = 3) -> str:
    """The path of :func:`stacked_plates` as a ``.usda`` in the cache (written when its text changed)."""
    from wsoft.env import cache_dir

    folder = cache_dir() / "stages"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"stacked_plates_{plates}.usda"
    stage = stacked_plates(plates)  # held: the layer lives as long as its stage
    text = stage.GetRootLayer().ExportToString()
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    return str(path)
