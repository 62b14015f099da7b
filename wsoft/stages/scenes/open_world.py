"""``open_world``: a 3 km square of procedural terrain (a heightfield mesh of about 1M triangles),
19,571 trees, rocks and houses placed by one PointInstancer, a sun of USD ``angle`` 0.53 degrees and
a camera 2 m above the ground looking to the horizon; and its two sequences, ``open_world_flyby``
(48 frames, the camera flying low, the sun still) and ``open_world_sunset`` (the same flight with
the sun sinking and turning: the time of day).

Large worlds are where one shadow map cannot cover the view: near the camera the shadows of rocks
1 m away need centimetre texels, and the hills 2 km away are still in view (cascades, virtual
shadow maps). The heightfield is computed from a fixed seed (value-noise fBm) and written as a
plain ``UsdGeom.Mesh`` of quads (the points are most of the file: about 6 MB); the instances are
the forest's kind (:mod:`wsoft.stages.scenes.forest`): prototypes of 20 to 468 triangles placing
about 5M triangles, more than ``instancing=auto`` flattens (:data:`wsoft.pipeline.loading.AUTO_KEEP_TRIANGLES`),
so the stage loads with its instances kept (seconds); a technique that needs the soup (dcs, izb,
pwedge, salzman) is refused with a one-line error, as the stage holds more than
:data:`~wsoft.pipeline.loading.FLATTEN_LIMIT` triangles.

:data:`SIZES` holds the full stage and a ``tiny`` one (a 64 x 64 heightfield, 400 instances: the
same layout at a test's size); :func:`write_world` writes all three stages at either size into a
folder.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdRender, Vt

from wsoft.stages.builders import add_material, add_mesh, add_sun, check_points_down, look_at_xform, make_stage, set_doc_string
from wsoft.stages.mesh import MeshData, box_mesh, merge_meshes, prism_z, triangle_count, weld, z_sphere
from wsoft.stages.scenes import APERTURES, add_scene_camera
from wsoft.stages.scenes.animated import FPS, frame_fraction, over_stage, stage_triangles, write_over


@dataclass(frozen=True)
class WorldSize:
    """How big an ``open_world`` is written."""

    grid: int
    """Heightfield cells along each side (``grid``² quads, 2 ``grid``² triangles)."""
    scattered: int
    """Instances spread over the whole terrain."""
    near: int
    """Instances in the wedge the camera sees within :data:`NEAR_RADIUS` m (the detail near it)."""
    houses: int
    """Houses and barns in the village ahead of the camera, besides ``near``."""


SIZES = {"full": WorldSize(grid=708, scattered=14_000, near=5_600, houses=400),
         "tiny": WorldSize(grid=64, scattered=240, near=140, houses=20)}

HALF = 1500.0              # the terrain spans [-HALF, HALF]^2 (m)
SEED = 20261207
AMPLITUDE = 90.0           # hills' height scale (m) far from the camera's path
FLAT_RADIUS = 260.0        # around the path the hills fade to gentle swells (m)
EYE_HEIGHT = 2.0           # the camera above the ground (m)
START = (-1100.0, -40.0)   # the camera's ground position at the first frame
HEADING = (0.0, 8.0)       # degrees from +x over the flight (a gentle left turn)
FLY_FRAMES = (1, 48)
FLY_STEP = 1.2             # metres a frame (29 m/s at 24 fps)
PITCH = -2.5               # the camera looks this many degrees below the horizon
NEAR_RADIUS = 350.0
CORRIDOR = 14.0            # no tree within this many metres of the flight line ahead of the camera (bushes and rocks from 2.5 m)
VILLAGE = (-650.0, 120.0, 140.0)   # centre (x, y) and radius of the houses (m)
SUN_ANGLE = 0.53           # USD DistantLight angle: the sun's full angular diameter (degrees)
SUN_ROTATE = (62.0, 0.0, 20.0)     # rotateXYZ: 28 degrees above the horizon, shadows toward +y across the flight line
SUNSET_ROTATE = ((62.0, 76.0), (20.0, 32.0))  # open_world_sunset: X tilt and Z turn from the first to the last frame
FOCAL = 20.0
CLIP = (0.1, 5000.0)
RESOLUTION = (640, 480)
FLY_CAMERA = "/World/FlyCamera"
FLY_SETTINGS = "/Render/FlyBy"


# -- terrain --------------------------------------------------------------------------------------


def value_noise(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, cells: int) -> np.ndarray:
    """Smoothly interpolated random lattice values in [-1, 1] at (x, y) in [0, 1]^2, ``cells`` lattice
    cells a side (smoothstep weights: continuous slope)."""
    lat = rng.uniform(-1.0, 1.0, (cells + 2, cells + 2))
    fx, fy = x * cells, y * cells
    ix, iy = np.minimum(fx.astype(np.int64), cells), np.minimum(fy.astype(np.int64), cells)
    tx, ty = fx - ix, fy - iy
    sx, sy = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
    a = lat[iy, ix] * (1 - sx) + lat[iy, ix + 1] * sx
    b = lat[iy + 1, ix] * (1 - sx) + lat[iy + 1, ix + 1] * sx
    return a * (1 - sy) + b * sy


def heights(grid: int, seed: int = SEED) -> np.ndarray:
    """The terrain's heights on its ``(grid + 1) x (grid + 1)`` points (row j: y, column i: x), in
    metres: fBm of :func:`value_noise` (6 octaves), the hills fading toward the flight path (a
    distance of :data:`FLAT_RADIUS` from the line y = START y) to swells of a few metres."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, grid + 1)
    x, y = np.meshgrid(u, u)
    h = np.zeros_like(x)
    for k in range(6):
        h += value_noise(rng, x, y, 4 * 2 ** k) * 0.5 ** k
    wy = (y * 2 - 1) * HALF
    d = np.abs(wy - START[1]) / FLAT_RADIUS
    fade = np.clip(d, 0.0, 1.0) ** 2
    swell = 3.0 * value_noise(rng, x, y, 48)
    return AMPLITUDE * fade * h + swell


def terrain_mesh(h: np.ndarray) -> MeshData:
    """The heightfield ``h`` (:func:`heights`) over [-HALF, HALF]^2 as a grid of quads, wound upward."""
    n = h.shape[0] - 1
    u = np.linspace(-HALF, HALF, n + 1)
    x, y = np.meshgrid(u, u)
    pts = np.stack([x.ravel(), y.ravel(), h.ravel()], axis=1)
    j, i = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    p0 = (j * (n + 1) + i).ravel()
    quads = np.stack([p0, p0 + 1, p0 + n + 2, p0 + n + 1], axis=1)
    return pts, [4] * (n * n), quads.ravel().tolist()


def ground_z(h: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The terrain's height at (x, y) on the triangles a quad (p0, p1, p2, p3) is split into by a fan
    from p0 ((p0, p1, p2) and (p0, p2, p3)): exact where the loader's triangles lie."""
    n = h.shape[0] - 1
    fx = (np.asarray(x) + HALF) / (2 * HALF) * n
    fy = (np.asarray(y) + HALF) / (2 * HALF) * n
    i = np.clip(fx.astype(np.int64), 0, n - 1)
    j = np.clip(fy.astype(np.int64), 0, n - 1)
    tx, ty = np.clip(fx - i, 0, 1), np.clip(fy - j, 0, 1)
    h0, h1, h2, h3 = h[j, i], h[j, i + 1], h[j + 1, i + 1], h[j + 1, i]
    lower = tx >= ty  # (p0, p1, p2): p0 + tx (p1 - p0) + ty (p2 - p1)
    return np.where(lower, h0 + tx * (h1 - h0) + ty * (h2 - h1), h0 + ty * (h3 - h0) + tx * (h2 - h3))


# -- prototypes -----------------------------------------------------------------------------------


def cone_mesh(n: int, radius: float, z0: float, z1: float) -> MeshData:
    """A closed cone: an n-gon base at z0 (facing -Z) and n triangles to the apex at z1."""
    th = 2.0 * math.pi * np.arange(n) / n
    pts = np.concatenate([np.stack([radius * np.cos(th), radius * np.sin(th), np.full(n, z0)], axis=1), [[0.0, 0.0, z1]]])
    idx = list(range(n))[::-1]
    for k in range(n):
        idx += [k, (k + 1) % n, n]
    return pts, [n] + [3] * n, idx


def squash(m: MeshData, s, t=(0.0, 0.0, 0.0)) -> MeshData:
    """``m`` scaled per axis by ``s``, then moved by ``t``."""
    return np.asarray(m[0]) * np.asarray(s, float) + np.asarray(t, float), m[1], m[2]


def rock_mesh(rng: np.random.Generator) -> MeshData:
    """A lumpy rock about 1 m across: a low sphere whose points are pushed in and out, half buried."""
    p, c, i = z_sphere(0.6, 14, 8)
    p = p * rng.uniform(0.75, 1.2, (len(p), 1)) * np.array([1.0, 0.8, 0.7]) + np.array([0.0, 0.0, 0.15])
    return p, c, i


def house_mesh(w: float, d: float, h: float, roof: float) -> MeshData:
    """A box house with a gable roof along x (two sloped quads and two gable triangles)."""
    walls = box_mesh((-w / 2, -d / 2, 0.0), (w / 2, d / 2, h))
    pts = np.array([[-w / 2 - 0.3, -d / 2 - 0.4, h], [w / 2 + 0.3, -d / 2 - 0.4, h], [w / 2 + 0.3, 0.0, h + roof], [-w / 2 - 0.3, 0.0, h + roof],
                    [-w / 2 - 0.3, d / 2 + 0.4, h], [w / 2 + 0.3, d / 2 + 0.4, h]])
    roof_m = (pts, [4, 4, 3, 3, 4], [0, 1, 2, 3, 5, 4, 3, 2, 0, 3, 4, 1, 5, 2, 4, 5, 1, 0])
    return merge_meshes([walls, roof_m])


def prototypes(rng: np.random.Generator) -> list[tuple[str, MeshData, tuple[float, float, float], float]]:
    """(name, mesh, colour, share of the scattered instances) of each prototype: two trees, a bush,
    a rock and two houses (houses are placed in the village only: share 0)."""
    pine = merge_meshes([prism_z(8, 0.2, 0.0, 3.0)] + [cone_mesh(24, 2.4 - 0.45 * k, 2.0 + 2.2 * k, 6.5 + 1.8 * k) for k in range(4)])
    oak = merge_meshes([prism_z(8, 0.3, 0.0, 3.5), squash(z_sphere(1.0, 20, 12), (3.2, 3.2, 2.6), (0.0, 0.0, 5.5))])
    bush = squash(z_sphere(1.0, 12, 7), (1.1, 1.1, 0.8), (0.0, 0.0, 0.55))
    return [("Pine", pine, (0.16, 0.33, 0.15), 0.40), ("Oak", oak, (0.22, 0.40, 0.16), 0.25),
            ("Bush", bush, (0.25, 0.42, 0.18), 0.20), ("Rock", rock_mesh(rng), (0.45, 0.44, 0.42), 0.15),
            ("House", house_mesh(8.0, 6.0, 3.0, 2.2), (0.70, 0.62, 0.52), 0.0),
            ("Barn", house_mesh(14.0, 9.0, 5.0, 3.5), (0.55, 0.25, 0.20), 0.0)]


# -- the camera -----------------------------------------------------------------------------------


def fly_path(h: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """The camera at the fraction ``s`` of the flight: its eye (:data:`EYE_HEIGHT` above the ground)
    and the point it looks at (ahead along its heading, :data:`PITCH` below the horizon)."""
    n = FLY_FRAMES[1] - FLY_FRAMES[0]
    h0, h1 = (math.radians(a) for a in HEADING)
    length = FLY_STEP * n
    a = h0 + s * (h1 - h0)
    if h1 == h0:
        x, y = START[0] + s * length * math.cos(h0), START[1] + s * length * math.sin(h0)
    else:
        r = length / (h1 - h0)
        x = START[0] + r * (math.sin(a) - math.sin(h0))
        y = START[1] - r * (math.cos(a) - math.cos(h0))
    z = float(ground_z(h, np.array([x]), np.array([y]))[0]) + EYE_HEIGHT
    eye = np.array([x, y, z])
    p = math.radians(PITCH)
    d = np.array([math.cos(a) * math.cos(p), math.sin(a) * math.cos(p), math.sin(p)])
    return eye, eye + 100.0 * d


# -- the stages -----------------------------------------------------------------------------------


def _scatter(rng: np.random.Generator, size: WorldSize, shares: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) and prototype index of every instance: ``scattered`` over the terrain, ``near`` in the
    camera's wedge, ``houses`` in the village; none on the flight line ahead of the camera, no tree or
    house within :data:`CORRIDOR` of it (the view reaches the horizon)."""
    n_tree = len(shares)
    xy = rng.uniform(-HALF + 5.0, HALF - 5.0, (size.scattered, 2))
    proto = rng.choice(n_tree, size=size.scattered, p=shares / shares.sum())
    r = NEAR_RADIUS * np.sqrt(rng.uniform((4.0 / NEAR_RADIUS) ** 2, 1.0, size.near))
    th = rng.uniform(-math.radians(50.0), math.radians(50.0), size.near)
    near = np.stack([eye[0] + r * np.cos(th), eye[1] + r * np.sin(th)], axis=1)
    near_proto = rng.choice(n_tree, size=size.near, p=shares / shares.sum())
    rv = VILLAGE[2] * np.sqrt(rng.uniform(0.0, 1.0, size.houses))
    tv = rng.uniform(0.0, 2.0 * math.pi, size.houses)
    village = np.stack([VILLAGE[0] + rv * np.cos(tv), VILLAGE[1] + rv * np.sin(tv)], axis=1)
    village_proto = np.where(rng.uniform(0, 1, size.houses) < 0.8, n_tree, n_tree + 1)
    xy = np.concatenate([xy, near, village])
    proto = np.concatenate([proto, near_proto, village_proto]).astype(np.int32)
    off = np.abs(xy[:, 1] - START[1])
    ahead = xy[:, 0] > START[0] - 20.0
    small = np.isin(proto, [2, 3])  # bushes and rocks: the detail a metre or two from the eye
    keep = ~ahead | (off > CORRIDOR) | (small & (off > 2.5))
    return xy[keep], proto[keep]


def scene_open_world(out_dir: str, size: str = "full") -> dict[str, object]:
    """The terrain, the PointInstancer, the sun and the camera: ``open_world.usdc``."""
    sz = SIZES[size]
    path = os.path.join(out_dir, "open_world.usdc")
    stage = make_stage("Z", path)
    rng = np.random.default_rng(SEED)
    h = heights(sz.grid)
    ground = terrain_mesh(h)
    add_mesh(stage, "/World/Terrain", ground, False, add_material(stage, "/World/Looks/Grass", (0.33, 0.36, 0.22)))
    ground_tris = triangle_count(ground[1])

    protos = prototypes(rng)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Scatter")
    UsdGeom.Scope.Define(stage, "/World/Scatter/Prototypes")
    paths, tris = [], []
    for name, mesh, color, _ in protos:
        root = "/World/Scatter/Prototypes/" + name
        UsdGeom.Xform.Define(stage, root)
        mesh = weld(mesh)
        add_mesh(stage, root + "/Mesh", mesh, False, add_material(stage, "/World/Looks/" + name, color))
        paths.append(Sdf.Path(root))
        tris.append(triangle_count(mesh[1]))
    pi.CreatePrototypesRel().SetTargets(paths)

    eye0, _ = fly_path(h, 0.0)
    shares = np.array([p[3] for p in protos if p[3] > 0])
    xy, proto = _scatter(rng, sz, shares, eye0)
    n = len(xy)
    z = ground_z(h, xy[:, 0], xy[:, 1]) - 0.1  # sunk a little: no gap under a trunk on a slope
    yaw = rng.uniform(0.0, 360.0, n)
    scale = np.round(rng.uniform(0.7, 1.35, n), 3)
    is_house = proto >= len(shares)
    scale[is_house] = 1.0
    pos = np.round(np.concatenate([xy, z[:, None]], axis=1), 3)
    half = np.radians(yaw) / 2
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(proto))
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pos, dtype=np.float32)))
    pi.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(float(c), 0.0, 0.0, float(s)) for c, s in zip(np.cos(half), np.sin(half))]))
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(np.repeat(scale[:, None], 3, axis=1), dtype=np.float32)))
    inst_tris = int(np.asarray(tris)[proto].sum())

    stage.DefinePrim("/World/Lights", "Xform")
    sun = add_sun(stage, "/World/Lights/Sun", SUN_ANGLE, SUN_ROTATE, intensity=3.0)
    check_points_down(sun.GetPrim(), (0, 0, -1), 0.4)
    eye, target = fly_path(h, 0.0)
    add_scene_camera(stage, tuple(eye), tuple(target), (0.0, 0.0, 1.0), focal=FOCAL, clip=CLIP)
    counts = np.bincount(proto, minlength=len(protos))
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc", (
        "open_world: a %g m square of terrain (/World/Terrain: a %d x %d heightfield, %d triangles, heights from seed %d, "
        "%.0f to %.0f m); %d instances (PointInstancer /World/Scatter: %s) of prototypes of %s triangles, %d instanced "
        "triangles; the sun /World/Lights/Sun (angle %g degrees, %g degrees above the horizon); the camera %g m above "
        "the ground at (%.0f, %.0f) looking along +x, %g degrees below the horizon, the terrain reaching %.0f m ahead."
        % (2 * HALF, sz.grid, sz.grid, ground_tris, SEED, h.min(), h.max(), n,
           ", ".join("%d %s" % (c, p[0].lower()) for c, p in zip(counts, protos)), ", ".join(map(str, tris)), inst_tris,
           SUN_ANGLE, 90.0 - SUN_ROTATE[0], EYE_HEIGHT, eye[0], eye[1], -PITCH, HALF - eye[0])))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": ground_tris + inst_tris, "instances": n, "prototype_triangles": tris}


def _base(out_dir: str, size: str) -> tuple[str, Usd.Stage]:
    f = os.path.join(out_dir, "open_world.usdc")
    if not os.path.isfile(f):
        scene_open_world(out_dir, size)
    return "open_world.usdc", Usd.Stage.Open(f)


def _fly_camera(stage: Usd.Stage, h: np.ndarray) -> None:
    cam = UsdGeom.Camera.Define(stage, FLY_CAMERA)
    cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    cam.CreateFocalLengthAttr(FOCAL)
    cam.CreateHorizontalApertureAttr(APERTURES["4:3"][0])
    cam.CreateVerticalApertureAttr(APERTURES["4:3"][1])
    cam.CreateClippingRangeAttr(Gf.Vec2f(*CLIP))
    op = cam.AddTransformOp()
    for f, s in frame_fraction(FLY_FRAMES):
        eye, target = fly_path(h, s)
        op.Set(look_at_xform(eye, target, (0.0, 0.0, 1.0)), Usd.TimeCode(f))
    settings = UsdRender.Settings.Define(stage, FLY_SETTINGS)
    settings.CreateResolutionAttr(Gf.Vec2i(*RESOLUTION))
    settings.CreateCameraRel().SetTargets([Sdf.Path(FLY_CAMERA)])
    stage.SetMetadata("renderSettingsPrimPath", FLY_SETTINGS)


def sunset_rotate(s: float) -> tuple[float, float, float]:
    """``open_world_sunset``'s sun rotateXYZ (degrees) at the fraction ``s`` of the flight."""
    (x0, x1), (z0, z1) = SUNSET_ROTATE
    return (x0 + s * (x1 - x0), 0.0, z0 + s * (z1 - z0))


def scene_open_world_flyby(out_dir: str, size: str = "full") -> dict[str, object]:
    """``open_world`` seen from a camera flying 2 m above the ground, the sun still: ``open_world_flyby.usda``."""
    path = os.path.join(out_dir, "open_world_flyby.usda")
    base_file, base = _base(out_dir, size)
    stage = over_stage(base, FLY_FRAMES)
    h = heights(SIZES[size].grid)
    _fly_camera(stage, h)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "open_world seen from a camera flying %g m above the ground (frames %d to %d at %g fps): %s sublayers %s and adds the "
        "camera %s, used through the render settings %s (%d x %d). The eye moves %g m a frame along a turn of its heading from "
        "%g to %g degrees from +x, following the ground; it looks %g degrees below the horizon. The sun stands still: "
        "what a shadow cache can keep from frame to frame." % (EYE_HEIGHT, *FLY_FRAMES, FPS, "open_world_flyby.usda", base_file,
                                                              FLY_CAMERA, FLY_SETTINGS, *RESOLUTION, FLY_STEP, *HEADING, -PITCH)))
    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}


def scene_open_world_sunset(out_dir: str, size: str = "full") -> dict[str, object]:
    """``open_world_flyby``'s flight with the sun sinking and turning (the time of day): ``open_world_sunset.usda``."""
    path = os.path.join(out_dir, "open_world_sunset.usda")
    base_file, base = _base(out_dir, size)
    stage = over_stage(base, FLY_FRAMES)
    h = heights(SIZES[size].grid)
    _fly_camera(stage, h)
    a, b = sunset_rotate(0.0), sunset_rotate(1.0)
    set_doc_string(stage.GetPrimAtPath("/World"), "wsoft:doc:motion", (
        "open_world_flyby's flight (frames %d to %d at %g fps) with the sun sinking and turning, the time of day: %s "
        "sublayers %s; /World/Lights/Sun's rotateXYZ goes linearly from (%g, %g, %g) to (%g, %g, %g), one sample per frame "
        "(its height above the horizon from %g to %g degrees): every frame the light moves, so a shadow cache keeps nothing."
        % (*FLY_FRAMES, FPS, "open_world_sunset.usda", base_file, *a, *b, 90.0 - a[0], 90.0 - b[0])))
    attr = stage.OverridePrim("/World/Lights/Sun").CreateAttribute("xformOp:rotateXYZ", Sdf.ValueTypeNames.Float3, custom=False)
    for f, s in frame_fraction(FLY_FRAMES):
        attr.Set(Gf.Vec3f(*sunset_rotate(s)), Usd.TimeCode(f))
    write_over(stage, base_file, path)
    return {"file": path, "triangles": stage_triangles(path)}


def write_world(out_dir: str, size: str = "full") -> dict[str, str]:
    """``open_world``, ``open_world_flyby`` and ``open_world_sunset`` at ``size`` (a key of :data:`SIZES`)
    in ``out_dir``: name -> file."""
    if size not in SIZES:
        raise ValueError(f"open_world size {size!r} is not one of {', '.join(SIZES)}")
    os.makedirs(out_dir, exist_ok=True)
    out = {"open_world": str(scene_open_world(out_dir, size)["file"])}
    out["open_world_flyby"] = str(scene_open_world_flyby(out_dir, size)["file"])
    out["open_world_sunset"] = str(scene_open_world_sunset(out_dir, size)["file"])
    return out
