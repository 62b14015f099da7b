"""``city``: about 1M triangles through native USD instancing (12 building prototypes, 344
instanceable Xforms), to test scale."""

from __future__ import annotations

import os

import numpy as np

from wsoft.stages.builders import (
    add_class_root,
    add_instance,
    add_material,
    add_mesh,
    add_rect_light,
    add_sun,
    check_points_down,
    make_stage,
)
from wsoft.stages.mesh import MeshData, box_mesh, merge_meshes, quad_mesh, triangle_count, weld
from wsoft.stages.scenes import add_scene_camera


def facade_wall(origin, u, count: int, floors: int, cell_w: float, floor_h: float,
                win_u: tuple[float, float], win_v: tuple[float, float],
                inset: float) -> MeshData:
    """Wall of count x floors cells, each with a recessed window.

    The wall spans origin + [0, count*cell_w] * u + [0, floors*floor_h] * Z and
    faces n = u x Z.  Each cell: 4 frame quads around the window opening,
    4 reveal quads and 1 recessed back quad (9 quads = 18 triangles).
    """
    o = np.asarray(origin, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    v = np.array([0.0, 0.0, 1.0])
    n = np.cross(u, v)
    pts: list[np.ndarray] = []
    idx: list[int] = []
    for j in range(floors):
        for i in range(count):
            base = len(pts)

            def P(a: float, b: float, d: float = 0.0) -> np.ndarray:
                return o + a * u + b * v - d * n

            x0, x1 = i * cell_w, (i + 1) * cell_w
            y0, y1 = j * floor_h, (j + 1) * floor_h
            wx0, wx1 = x0 + win_u[0] * cell_w, x0 + win_u[1] * cell_w
            wy0, wy1 = y0 + win_v[0] * floor_h, y0 + win_v[1] * floor_h
            pts += [P(x0, y0), P(x1, y0), P(x1, y1), P(x0, y1),                  # O 0..3
                    P(wx0, wy0), P(wx1, wy0), P(wx1, wy1), P(wx0, wy1),          # I 4..7
                    P(wx0, wy0, inset), P(wx1, wy0, inset),
                    P(wx1, wy1, inset), P(wx0, wy1, inset)]                      # B 8..11
            for k in range(4):
                k1 = (k + 1) % 4
                idx += [base + k, base + k1, base + 4 + k1, base + 4 + k]        # frame
                idx += [base + 4 + k, base + 4 + k1, base + 8 + k1, base + 8 + k]  # reveal
            idx += [base + 8, base + 9, base + 10, base + 11]                    # back
    return np.asarray(pts), [4] * (len(idx) // 4), idx


def building_mesh(cx: int, cy: int, floors: int, cell_w: float, floor_h: float,
                  win_u, win_v, inset: float, roof_box: tuple[float, float, float]) -> MeshData:
    """A box building with ``cx`` and ``cy`` window cells along its sides and ``floors`` floors
    (recessed windows), a flat roof and a penthouse box on it, welded into one mesh."""
    W, D, H = cx * cell_w, cy * cell_w, floors * floor_h
    walls = [
        facade_wall((-W / 2, -D / 2, 0), (1, 0, 0), cx, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((W / 2, -D / 2, 0), (0, 1, 0), cy, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((W / 2, D / 2, 0), (-1, 0, 0), cx, floors, cell_w, floor_h, win_u, win_v, inset),
        facade_wall((-W / 2, D / 2, 0), (0, -1, 0), cy, floors, cell_w, floor_h, win_u, win_v, inset),
    ]
    roof = quad_mesh([(-W / 2, -D / 2, H), (W / 2, -D / 2, H), (W / 2, D / 2, H), (-W / 2, D / 2, H)])
    rw, rd, rh = roof_box
    pent = box_mesh((-rw / 2, -rd / 2, H), (rw / 2, rd / 2, H + rh))
    # drop the penthouse bottom face (first quad, -Z): it lies on the roof
    pent = (pent[0], pent[1][1:], pent[2][4:])
    return weld(merge_meshes(walls + [roof, pent]))


CITY_PROTOTYPES = [
    # (cells x, cells y, floors, cell width, floor height)
    (3, 3, 10, 3.0, 3.5),
    (4, 4, 10, 3.0, 3.5),
    (4, 3, 12, 3.0, 3.5),
    (5, 3, 10, 3.0, 3.5),
    (5, 5, 8, 3.0, 4.0),
    (3, 2, 20, 3.0, 3.5),
    (6, 4, 8, 3.0, 3.0),
    (4, 4, 13, 3.0, 3.5),
    (6, 3, 7, 3.0, 4.0),
    (3, 3, 16, 3.0, 3.5),
    (5, 4, 9, 3.0, 3.5),
    (2, 2, 25, 3.5, 3.5),
]


def scene_city(out_dir: str) -> dict[str, object]:
    """12 building prototypes on a jittered 19 x 19 grid of instanceable Xforms, a sun and a rect
    light: ``city.usdc``."""
    path = os.path.join(out_dir, "city.usdc")
    stage = make_stage("Z", path)
    rng = np.random.default_rng(20240611)

    # Prototypes: a class root (abstract, never rendered itself).
    add_class_root(stage, "/Prototypes")
    proto_tris: list[int] = []
    for k, (cx, cy, fl, cw, fh) in enumerate(CITY_PROTOTYPES):
        ppath = "/Prototypes/Building%02d" % k
        stage.DefinePrim(ppath, "Xform")
        win_u = (0.2 + 0.05 * (k % 3), 0.8 - 0.05 * (k % 3))
        win_v = (0.25, 0.8 - 0.05 * (k % 2))
        inset = 0.25 + 0.05 * (k % 4)
        roof_box = (cx * cw * 0.4, cy * cw * 0.4, 2.0 + (k % 3))
        m = building_mesh(cx, cy, fl, cw, fh, win_u, win_v, inset, roof_box)
        grey = 0.45 + 0.04 * (k % 6)
        tint = ((k * 37) % 11) / 100.0
        mat = add_material(stage, ppath + "/Looks/Facade",
                           (grey + tint, grey, grey - tint * 0.5))
        add_mesh(stage, ppath + "/Mesh", m, False, mat)
        proto_tris.append(triangle_count(m[1]))

    ground = quad_mesh([(-400, -400, 0), (400, -400, 0), (400, 400, 0), (-400, 400, 0)])
    add_mesh(stage, "/World/Ground", ground, False,
             add_material(stage, "/World/Looks/GroundMat", (0.35, 0.35, 0.33)))
    total = triangle_count(ground[1])

    stage.DefinePrim("/World/City", "Xform")
    n_side, spacing = 19, 32.0
    n_inst = 0
    for r in range(n_side):
        for c in range(n_side):
            skip = rng.random() < 0.06
            proto = int(rng.integers(0, len(CITY_PROTOTYPES)))
            rot = 90.0 * int(rng.integers(0, 4))
            hscale = float(np.round(rng.uniform(0.7, 1.5), 3))
            jitter = np.round(rng.uniform(-2.0, 2.0, size=2), 3)
            if skip:  # open plaza
                continue
            x = (c - (n_side - 1) / 2) * spacing + float(jitter[0])
            y = (r - (n_side - 1) / 2) * spacing + float(jitter[1])
            add_instance(stage, "/World/City/B_%02d_%02d" % (r, c), "/Prototypes/Building%02d" % proto,
                         (x, y, 0.0), rot, (1.0, 1.0, hscale))
            total += proto_tris[proto]
            n_inst += 1

    stage.DefinePrim("/World/Lights", "Xform")
    sun = add_sun(stage, "/World/Lights/Sun", 1.0, (40.0, 0.0, 35.0), intensity=3.0)
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.7)

    rect = add_rect_light(stage, "/World/Lights/Rect", (0.0, 0.0, 250.0), 4.0, 4.0, intensity=5000.0)
    check_points_down(rect.GetPrim(), (0, 0, -1), 0.999)

    add_scene_camera(stage, (-450.0, -540.0, 330.0), (15.0, 25.0, 0.0), (0.0, 0.0, 1.0),
                     focal=26.0, clip=(1.0, 5000.0))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": total, "instances": n_inst,
            "prototype_triangles": proto_tris}
