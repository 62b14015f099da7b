"""Small stages that separate the causes of Fig. 12's ranking (micropatches against microrects at
coarse levels), for the ``ssm`` sweep and ``tests/test_ssm.py``:

* ``plate_aligned`` — one solid square plate, its edges along the light view's axes, over a
  parallel ground under a parallel square rect light: the simplest occluder for microrects;
* ``plate_rotated`` — one solid square plate turned 30° in the light's view, over a ground: a solid
  planar occluder, where a microrect (a merged block's bounding box at its nearest depth) fits the
  plate better than aligned micropatches, so microrects must win;
* ``plate_holes`` — the same plate with a 4 x 4 grid of square holes: §5's bounding-box union
  closes holes narrower than a coarse cell, so microrects are expected to lose here;
* ``plates_stacked`` — two plates at different heights, overlapping in the light's view: a merge
  across the depth jump takes the nearer plate's depth for members of the farther one.

Each is written once as a ``.usda`` into ``$WSOFT_CACHE_DIR/stages`` (default
``~/.cache/wsoft/stages``; rewritten only when its text changes, so cached references stay valid)
and the sweep names it by that path.
"""

from __future__ import annotations

import os

from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_rect_light, make_stage


def _plate(stage, path: str, center, half: float, holes: int = 0, rotate: float = 0.0):
    """A horizontal square plate (double-sided), optionally with ``holes`` x ``holes`` square holes
    of a third of their cell, turned ``rotate`` degrees about the vertical axis."""
    from pxr import Gf, UsdGeom

    cx, cy, cz = center
    n = 3 * holes if holes else 1
    step = 2.0 * half / n
    pts, counts, idx = [], [], []
    for j in range(n):
        for i in range(n):
            if holes and i % 3 == 1 and j % 3 == 1:
                continue  # the hole in the middle of each 3 x 3 block
            x0, y0 = -half + i * step, -half + j * step
            k = len(pts)
            pts += [(x0, y0, 0.0), (x0 + step, y0, 0.0), (x0 + step, y0 + step, 0.0), (x0, y0 + step, 0.0)]
            counts.append(4)
            idx += [k, k + 1, k + 2, k + 3]
    m = add_mesh(stage, path, (pts, counts, idx), True, minimal=True)
    xf = UsdGeom.XformCommonAPI(m)
    xf.SetTranslate(Gf.Vec3d(cx, cy, cz))
    xf.SetRotate(Gf.Vec3f(0.0, 0.0, rotate))
    return m


def build(name: str):
    """The in-memory stage ``name`` (one of :data:`NAMES`)."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    if name == "plate_aligned":
        _plate(st, "/World/Plate", (0, 0, 1.0), 1.2)
    elif name == "plate_rotated":
        _plate(st, "/World/Plate", (0, 0, 1.0), 1.2, rotate=30.0)
    elif name == "plate_holes":
        _plate(st, "/World/Plate", (0, 0, 1.0), 1.2, holes=4, rotate=30.0)
    elif name == "plates_stacked":
        _plate(st, "/World/Low", (-0.4, 0, 0.8), 0.9, rotate=30.0)
        _plate(st, "/World/High", (0.5, 0.2, 1.6), 0.7, rotate=10.0)
    else:
        raise KeyError(name)
    add_rect_light(st, "/World/Light", (0, 0, 4), 1.5, 1.5)
    add_camera(st, "/World/Cam", (0, -5.5, 5.5), (0, 0, 0.3), focal=20)
    return st


NAMES = ("plate_aligned", "plate_rotated", "plate_holes", "plates_stacked")


def stage_file(name: str) -> str:
    """The path of stage ``name`` as a ``.usda`` in the cache (written when its text changed)."""
    from wsoft.env import cache_dir

    folder = cache_dir() / "stages"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"ssm_{name}.usda"
    stage = build(name)  # held: the layer lives as long as its stage
    text = stage.GetRootLayer().ExportToString()
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    return str(path)
