"""Stages for omnidirectional (cube-map) shadows: a point light at the centre of a closed box.

:func:`closed_box_point` writes one variant of it into a folder; the tests of the local lights'
cube maps read them (``hard`` against the reference's one-sample answer on every wall, filter
kernels across a face edge, a light on a face-boundary direction, a receiver at the light).
"""

from __future__ import annotations

import os

import numpy as np

from wsoft.stages.builders import add_camera, add_material, add_mesh, add_point_light, add_sphere_light, make_stage, set_doc_string
from wsoft.stages.mesh import MeshData, grid_quad_mesh, quad_mesh

BOX_HALF = 2.0  # the box's inside spans [-2, 2] on every axis, the light at its centre
WALL_CELLS = 4  # each wall a 4 x 4 grid of quads
OCCLUDER_AT = 1.0  # a wall's occluder lies this far from the centre along the wall's axis (1.0 off the wall)
OCCLUDER_HALF = 0.3  # its half-side: its shadow on the wall, twice the occluder, has half-side 0.6
# in-plane offset (along the wall's first and second axes) of each wall's occluder, so that no
# shadow is centred on its face's axis and no two are alike
OCCLUDER_OFFSETS = {"PX": (0.25, 0.15), "NX": (-0.3, 0.2), "PY": (0.2, -0.25), "NY": (-0.15, -0.3), "PZ": (0.3, 0.1), "NZ": (-0.2, 0.3)}
VARIANTS = ("walls", "seams", "receiver_at_light")

# wall name -> (axis, sign): the wall lies at sign * BOX_HALF on the axis
WALLS = {"PX": (0, 1), "NX": (0, -1), "PY": (1, 1), "NY": (1, -1), "PZ": (2, 1), "NZ": (2, -1)}


def _frame(axis: int, sign: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, u, v) of a wall: its outward axis ``n`` (away from the centre) and two in-plane axes
    with ``u x v = -n``, so that a quad wound along (u, v) faces the centre."""
    n = np.zeros(3)
    n[axis] = sign
    u = np.zeros(3)
    u[(axis + 1) % 3] = 1.0
    v = np.cross(-n, u)
    return n, u, v


def _wall(name: str) -> MeshData:
    """The wall ``name``: a grid of WALL_CELLS x WALL_CELLS quads facing the centre."""
    n, u, v = _frame(*WALLS[name])
    h = BOX_HALF
    return grid_quad_mesh(h * n - h * u - h * v, 2 * h * u, 2 * h * v, WALL_CELLS, WALL_CELLS)


def _square(center, normal, half: float) -> MeshData:
    """A square of half-side ``half`` centred at ``center``, perpendicular to ``normal`` (wound
    counter-clockwise seen from the side ``normal`` points to)."""
    c = np.asarray(center, np.float64)
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    ref = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = np.cross(n, ref)
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    return quad_mesh([c + half * (-a - b), c + half * (a - b), c + half * (a + b), c + half * (-a + b)])


def wall_occluder(name: str) -> MeshData:
    """The occluder near the wall ``name``: a square of half-side OCCLUDER_HALF parallel to the
    wall at OCCLUDER_AT from the centre, moved by OCCLUDER_OFFSETS[name] within its plane."""
    n, u, v = _frame(*WALLS[name])
    du, dv = OCCLUDER_OFFSETS[name]
    c = OCCLUDER_AT * n + du * u + dv * v
    return quad_mesh([c - OCCLUDER_HALF * u - OCCLUDER_HALF * v, c + OCCLUDER_HALF * u - OCCLUDER_HALF * v,
                      c + OCCLUDER_HALF * u + OCCLUDER_HALF * v, c - OCCLUDER_HALF * u + OCCLUDER_HALF * v])


# the seams variant's occluders: (name, centre, normal): one on the direction between +X and +Y
# (the cube faces' boundary |x| = |y|; its shadow straddles the box's edge x = y = 2), one on the
# direction of the corner (-1, 1, 1) (three faces meet; its shadow straddles that corner)
SEAM_OCCLUDERS = (("Edge", (1.0, 1.0, 0.3), (1.0, 1.0, 0.0)), ("Corner", (-0.8, 0.8, 0.8), (-1.0, 1.0, 1.0)))
SEAM_HALF = 0.25

CAM_BACK, CAM_SIDE, CAM_FOCAL = 0.2, 1.5, 12.0


def wall_camera(name: str):
    """(eye, target, up) of the camera of the wall ``name``: CAM_BACK behind the centre and CAM_SIDE
    off it along both in-plane axes (off the light, so that the occluder does not hide its own
    shadow), aimed at the centre of the occluder's shadow on the wall."""
    n, u, v = _frame(*WALLS[name])
    du, dv = OCCLUDER_OFFSETS[name]
    eye = -CAM_BACK * n + CAM_SIDE * (u + v)
    target = BOX_HALF * n + (BOX_HALF / OCCLUDER_AT) * (du * u + dv * v)
    return tuple(eye), tuple(target), tuple(v)


RECEIVER_AT_LIGHT = ((-0.05, -0.05, 0.0), (0.05, -0.05, 0.0), (0.0, 0.08, 0.0))  # contains the centre; facing +Z


def closed_box_point(folder: str, variant: str = "walls", *, radius: float = 0.0) -> str:
    """Write the closed box with a light at its centre, as ``folder/closed_box_point_<variant>.usda``;
    its path.

    Every variant: a box whose inside spans ``[-2, 2]`` on every axis, its six walls
    (``/World/Walls/{PX, NX, PY, NY, PZ, NZ}``: P/N the sign of the axis the wall lies on) double-sided
    grids of 4 x 4 quads; the light ``/World/Light`` at the origin, a point light (SphereLight of
    radius 0 with ``treatAsPoint``) or, with ``radius`` > 0, a SphereLight of that radius. The six
    occluders ``/World/Occluders/{PX, ...}`` are double-sided squares of half-side 0.3 parallel to
    their wall, 1.0 from the centre (1.0 off the wall), moved within their plane by
    ``OCCLUDER_OFFSETS``: each casts a square shadow of half-side 0.6 on its own wall only, inside
    that wall's cube face (no shadow reaches a face edge). Seen from the light, each wall fills
    exactly one face of an axis-aligned cube map. Cameras (square, 24 mm aperture):
    ``/World/Camera`` (12 mm focal, 90 degrees) in the corner (-1.6, -1.7, -1.3) looking at
    (1, 1, 0.8), seeing the walls PX, PY and PZ and parts of the others; and
    ``/World/Cameras/{PX, ...}`` (:func:`wall_camera`), each 0.2 behind the centre and 1.5 off it
    along both in-plane axes of its wall, aimed at its occluder's shadow, which it sees (the
    occluder hides part of it) with about 0.45 of its frame on that wall.

    ``variant``:

    - ``"walls"``: the above.
    - ``"seams"``: the light exactly on face-boundary directions relative to two more occluders
      (double-sided squares of half-side 0.25 facing the light): ``/World/Occluders/Edge``
      centred at (1, 1, 0.3), on the boundary between the +X and +Y faces, whose shadow straddles
      the box's edge x = y = 2 (half on wall PX, half on PY); and ``/World/Occluders/Corner``
      centred at (-0.8, 0.8, 0.8), on the direction where the -X, +Y and +Z faces meet, whose
      shadow straddles the box's corner (-2, 2, 2) on three walls. ``/World/Camera`` sees both.
    - ``"receiver_at_light"``: a tiny triangle ``/World/AtLight`` (double-sided, in the plane
      z = 0, about 0.1 across) that contains the light's centre: a receiver (and caster) at the
      light's position, edge-on to the light. ``/World/Camera`` is at (0, -0.25, 0.25) looking at
      the origin, the triangle in the middle of its frame: about 1% of a 160 x 160 frame's pixels
      lie on it, within 0.1 of the light's centre (the nearest within a pixel's footprint of it).
    """
    if variant not in VARIANTS:
        raise ValueError(f"closed_box_point: unknown variant {variant!r} (choose from {', '.join(VARIANTS)})")
    if not radius >= 0.0:
        raise ValueError(f"closed_box_point: radius {radius!r} must be >= 0")
    st = make_stage()
    wall_mat = add_material(st, "/World/Looks/WallMat", (0.8, 0.8, 0.8))
    occ_mat = add_material(st, "/World/Looks/OccluderMat", (0.8, 0.3, 0.2))
    st.DefinePrim("/World/Walls", "Xform")
    st.DefinePrim("/World/Occluders", "Xform")
    for name in WALLS:
        add_mesh(st, "/World/Walls/" + name, _wall(name), True, wall_mat)
        add_mesh(st, "/World/Occluders/" + name, wall_occluder(name), True, occ_mat)
    if variant == "seams":
        for name, c, n in SEAM_OCCLUDERS:
            add_mesh(st, "/World/Occluders/" + name, _square(c, n, SEAM_HALF), True, occ_mat)
    if variant == "receiver_at_light":
        add_mesh(st, "/World/AtLight", (np.asarray(RECEIVER_AT_LIGHT, np.float64), [3], [0, 1, 2]), True, occ_mat)
    if radius > 0.0:
        add_sphere_light(st, "/World/Light", (0.0, 0.0, 0.0), radius, intensity=10.0)
    else:
        add_point_light(st, "/World/Light", (0.0, 0.0, 0.0), intensity=10.0, radius=0.0)
    square = dict(focal=12.0, aperture=(24.0, 24.0), clip=(0.01, 20.0), projection=True)
    if variant == "receiver_at_light":
        add_camera(st, "/World/Camera", (0.0, -0.25, 0.25), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), **square)
    else:
        add_camera(st, "/World/Camera", (-1.6, -1.7, -1.3), (1.0, 1.0, 0.8), (0.0, 0.0, 1.0), **square)
    st.DefinePrim("/World/Cameras", "Xform")
    for name in WALLS:
        eye, target, up = wall_camera(name)
        add_camera(st, "/World/Cameras/" + name, eye, target, up, **dict(square, focal=CAM_FOCAL))
    set_doc_string(st.GetPrimAtPath("/World"), "wsoft:doc", (
        f"closed_box_point, variant {variant}: a light at the centre of a closed box [-2, 2]^3 "
        f"({'a point light' if radius == 0.0 else f'a SphereLight of radius {radius:g}'}), one occluder near each wall "
        "(see wsoft.stages.omni_cases.closed_box_point)."))
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"closed_box_point_{variant}.usda")
    st.GetRootLayer().Export(path)
    return path
