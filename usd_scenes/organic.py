"""Organic paper-analog scenes for generate.py: creatures, plants and trees.

Analogs of the test scenes of Shen, Feng and Yang's exponential soft shadow
mapping (ESSM, Table 1: Ogre, Plants, Dinosaurs) and of Schwarz and
Stamminger 2008 (bitmask soft shadows, Figs. 1, 8, 10 and Table 2).  All
geometry is procedural: swept tubes and curved leaf strips displaced by smooth,
seeded sums of sinusoids, so every run writes byte-identical files.

Only called through ``generate.py`` (``--only ogre plants ...``).
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Sequence

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from generate import (
    MeshData,
    check_points_down,
    look_at_xform,
    make_camera,
    make_material,
    make_mesh,
    merge_meshes,
    new_stage,
    quad_mesh,
    set_doc_string,
    triangle_count,
)

# ---------------------------------------------------------------------------
# Smooth deterministic noise and swept tubes
# ---------------------------------------------------------------------------


class Ripple:
    """Smooth periodic-in-angle noise: sum of sin(2 pi f t + k theta + phase).

    Frequencies f, integer angular frequencies k and phases come from a seeded
    generator; the result lies roughly in [-1, 1].
    """

    def __init__(self, seed: int, terms: int = 6, fmax: float = 4.0, kmax: int = 4):
        rng = np.random.default_rng(seed)
        self.f = rng.uniform(0.5, fmax, size=terms)
        self.k = rng.integers(0, kmax + 1, size=terms).astype(np.float64)
        self.ph = rng.uniform(0.0, 2.0 * math.pi, size=terms)
        self.a = 1.0 / (1.0 + np.arange(terms))
        self.a /= self.a.sum()

    def __call__(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        out = np.zeros(np.broadcast(t, theta).shape)
        for f, k, ph, a in zip(self.f, self.k, self.ph, self.a):
            out += a * np.sin(2.0 * math.pi * f * t + k * theta + ph)
        return out


def polyline(ctrl: Sequence[Sequence[float]]) -> Callable[[np.ndarray], np.ndarray]:
    """Smooth curve through control points (Catmull-Rom), parameter t in [0, 1]."""
    c = np.asarray(ctrl, dtype=np.float64)
    c = np.concatenate([2 * c[:1] - c[1:2], c, 2 * c[-1:] - c[-2:-1]], axis=0)
    n_seg = len(ctrl) - 1

    def curve(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        s = np.clip(t, 0.0, 1.0) * n_seg
        i = np.minimum(s.astype(np.int64), n_seg - 1)
        u = (s - i)[:, None]
        p0, p1, p2, p3 = c[i], c[i + 1], c[i + 2], c[i + 3]
        return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u * u
                      + (-p0 + 3 * p1 - 3 * p2 + p3) * u * u * u)

    return curve


def tube(curve: Callable[[np.ndarray], np.ndarray],
         radius: Callable[[np.ndarray, np.ndarray], np.ndarray],
         n_along: int, n_around: int, caps: bool = True) -> MeshData:
    """Closed swept tube: n_along rings of n_around points around `curve`.

    Rings sit at t = (1 - cos(pi k / (n_along + 1))) / 2, k = 1..n_along (dense
    near the ends, like sphere stacks); with caps, pole points at curve(0) and
    curve(1) close the ends with triangle fans.  radius(t (n,1), theta (1,m))
    gives the ring radii.  Frames are parallel-transported along the curve.
    Quads between rings, wound outward.  Triangles: 2 * n_along * n_around
    with caps.
    """
    k = np.arange(1, n_along + 1, dtype=np.float64)
    t = 0.5 - 0.5 * np.cos(math.pi * k / (n_along + 1))
    c = curve(t)
    eps = 1e-4
    tan = curve(np.minimum(t + eps, 1.0)) - curve(np.maximum(t - eps, 0.0))
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tan[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    nrm = np.empty_like(tan)
    n0 = np.cross(ref, tan[0])
    nrm[0] = n0 / np.linalg.norm(n0)
    for i in range(1, len(t)):
        v = nrm[i - 1] - np.dot(nrm[i - 1], tan[i]) * tan[i]
        nrm[i] = v / np.linalg.norm(v)
    bin_ = np.cross(tan, nrm)
    th = 2.0 * math.pi * np.arange(n_around) / n_around
    r = radius(t[:, None], th[None, :])
    pts = (c[:, None, :] + r[:, :, None] * (np.cos(th)[None, :, None] * nrm[:, None, :]
                                             + np.sin(th)[None, :, None] * bin_[:, None, :]))
    pts = pts.reshape(-1, 3)
    ring = np.arange(n_along * n_around).reshape(n_along, n_around)
    nxt = np.roll(ring, -1, axis=1)
    quads = np.stack([ring[:-1], nxt[:-1], nxt[1:], ring[1:]], axis=-1).reshape(-1, 4)
    counts = [4] * len(quads)
    idx = quads.reshape(-1).tolist()
    if caps:
        s, e = len(pts), len(pts) + 1
        pts = np.concatenate([pts, curve(np.array([0.0, 1.0]))], axis=0)
        first, last = ring[0], ring[-1]
        fan_s = np.stack([np.full(n_around, s), np.roll(first, -1), first], axis=-1)
        fan_e = np.stack([np.full(n_around, e), last, np.roll(last, -1)], axis=-1)
        counts += [3] * (2 * n_around)
        idx += fan_s.reshape(-1).tolist() + fan_e.reshape(-1).tolist()
    return pts, counts, idx


def rounded(profile: Callable[[np.ndarray], np.ndarray], power: float = 0.5,
            bump: float = 0.0, seed: int = 0, fmax: float = 4.0, kmax: int = 4
            ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Radius function profile(t) * sin(pi t)^power * (1 + bump * noise(t, theta))."""
    noise = Ripple(seed, fmax=fmax, kmax=kmax) if bump else None

    def radius(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        r = profile(t) * np.sin(math.pi * t) ** power
        r = np.broadcast_to(r, np.broadcast(t, theta).shape).copy()
        if noise is not None:
            r *= 1.0 + bump * noise(t, theta)
        return r

    return radius


def lerp_profile(values: Sequence[float]) -> Callable[[np.ndarray], np.ndarray]:
    """Piecewise-linear radius profile through `values` at equally spaced t."""
    xs = np.linspace(0.0, 1.0, len(values))
    vs = np.asarray(values, dtype=np.float64)
    return lambda t: np.interp(t, xs, vs)


def signed_volume_np(m: MeshData) -> float:
    """Signed volume (fan-triangulated faces), vectorised."""
    p, counts, idx = m
    counts = np.asarray(counts)
    idx = np.asarray(idx)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vol = 0.0
    for c in np.unique(counts):
        st = starts[counts == c]
        for k in range(1, c - 1):
            a, b, d = p[idx[st]], p[idx[st + k]], p[idx[st + k + 1]]
            vol += float(np.einsum("ij,ij->i", a, np.cross(b, d)).sum())
    return vol / 6.0


def flatten_below(m: MeshData, z0: float = 0.0) -> MeshData:
    """Clamp z >= z0: the parts pushed below the ground become flat soles on it."""
    p = m[0].copy()
    p[:, 2] = np.maximum(p[:, 2], z0)
    return p, m[1], m[2]


# ---------------------------------------------------------------------------
# Creature: body, neck, head, four legs, tail (and horns), Z up, facing +X
# ---------------------------------------------------------------------------

CREATURE_BASE = {
    # part: (n_along, n_around) at res 1
    "body": (60, 48), "neck": (36, 28), "head": (36, 32), "leg": (40, 20),
    "tail": (44, 20), "horn": (10, 8),
}


def creature_parts(res: float, kind: str, seed: int) -> list[MeshData]:
    """Closed parts of a quadruped about 2.5 units tall; feet flattened onto z = 0.

    kind 'ogre': bulky body, short thick neck, big head with horns.
    kind 'sauropod': long neck and tail, small head.
    kind 'raptor': short body leaning forward, big head, long tail.
    """
    def n(part: str) -> tuple[int, int]:
        a, b = CREATURE_BASE[part]
        return max(3, round(a * res)), max(6, round(b * res))

    parts: list[MeshData] = []
    rng = np.random.default_rng(seed)
    if kind == "ogre":
        body_c = [(-1.0, 0.0, 1.35), (-0.2, 0.0, 1.55), (0.7, 0.0, 1.6), (1.15, 0.0, 1.7)]
        body_r = [0.55, 0.72, 0.78, 0.6]
        neck_c = [(0.9, 0.0, 1.75), (1.25, 0.0, 2.05), (1.45, 0.0, 2.2)]
        neck_r = [0.42, 0.36, 0.34]
        head_c = [(1.25, 0.0, 2.25), (1.7, 0.0, 2.3), (2.15, 0.0, 2.1)]
        head_r = [0.4, 0.42, 0.26]
        tail_c = [(-0.9, 0.0, 1.35), (-1.5, 0.0, 1.0), (-2.0, 0.0, 0.75), (-2.4, 0.0, 0.7)]
        tail_r = [0.3, 0.2, 0.12, 0.06]
        leg_hip = [(0.65, 0.4), (0.65, -0.4), (-0.6, 0.42), (-0.6, -0.42)]
        leg_top, leg_r = 1.45, [0.3, 0.24, 0.2, 0.19]
        horns = True
    elif kind == "sauropod":
        body_c = [(-1.1, 0.0, 1.3), (-0.3, 0.0, 1.5), (0.5, 0.0, 1.5), (1.0, 0.0, 1.45)]
        body_r = [0.5, 0.62, 0.6, 0.45]
        neck_c = [(0.8, 0.0, 1.5), (1.4, 0.0, 1.9), (1.8, 0.0, 2.5), (2.0, 0.0, 2.9)]
        neck_r = [0.3, 0.2, 0.15, 0.13]
        head_c = [(1.9, 0.0, 2.95), (2.15, 0.0, 3.0), (2.45, 0.0, 2.88)]
        head_r = [0.18, 0.2, 0.12]
        tail_c = [(-1.0, 0.0, 1.35), (-1.8, 0.0, 1.0), (-2.6, 0.0, 0.55), (-3.3, 0.0, 0.35)]
        tail_r = [0.28, 0.18, 0.09, 0.04]
        leg_hip = [(0.55, 0.35), (0.55, -0.35), (-0.65, 0.38), (-0.65, -0.38)]
        leg_top, leg_r = 1.35, [0.24, 0.2, 0.18, 0.17]
        horns = False
    else:  # raptor
        body_c = [(-0.8, 0.0, 1.35), (-0.1, 0.0, 1.45), (0.6, 0.0, 1.6), (0.9, 0.0, 1.75)]
        body_r = [0.4, 0.5, 0.48, 0.38]
        neck_c = [(0.7, 0.0, 1.7), (1.0, 0.0, 2.0), (1.15, 0.0, 2.2)]
        neck_r = [0.26, 0.22, 0.22]
        head_c = [(0.95, 0.0, 2.3), (1.4, 0.0, 2.35), (1.85, 0.0, 2.2)]
        head_r = [0.3, 0.28, 0.15]
        tail_c = [(-0.7, 0.0, 1.4), (-1.4, 0.0, 1.25), (-2.1, 0.0, 1.15), (-2.8, 0.0, 1.15)]
        tail_r = [0.28, 0.18, 0.09, 0.03]
        leg_hip = [(0.5, 0.3), (0.5, -0.3), (-0.45, 0.34), (-0.45, -0.34)]
        leg_top, leg_r = 1.4, [0.22, 0.16, 0.13, 0.14]
        horns = False

    def part(ctrl, prof, nn, power=0.55, bump=0.06, fmax=5.0, kmax=5):
        s = int(rng.integers(0, 2**31 - 1))
        parts.append(tube(polyline(ctrl), rounded(lerp_profile(prof), power, bump, s, fmax, kmax),
                          *nn))

    part(body_c, body_r, n("body"), power=0.45, bump=0.07)
    part(neck_c, neck_r, n("neck"), power=0.3, bump=0.05)
    part(head_c, head_r, n("head"), power=0.5, bump=0.08)
    part(tail_c, tail_r, n("tail"), power=0.25, bump=0.05)
    for i, (hx, hy) in enumerate(leg_hip):
        fx = hx + (0.12 if i < 2 else -0.1)
        fy = hy * 1.18
        knee = (hx + (0.05 if i < 2 else -0.12), hy * 1.1, 0.6 * leg_top)
        # the leg reaches below the ground and is clamped flat onto z = 0 (sole)
        ctrl = [(hx, hy, leg_top), knee, (fx, fy, 0.15), (fx + 0.06, fy, -0.12)]
        prof = leg_r[:3] + [leg_r[3] * 1.25]
        part(ctrl, prof, n("leg"), power=0.25, bump=0.05, fmax=3.0, kmax=3)
    if horns:
        hx, hz = head_c[1][0], head_c[1][2]
        for sy in (1.0, -1.0):
            ctrl = [(hx - 0.1, 0.22 * sy, hz + 0.25), (hx - 0.15, 0.42 * sy, hz + 0.5),
                    (hx - 0.35, 0.5 * sy, hz + 0.7)]
            part(ctrl, [0.1, 0.06, 0.02], n("horn"), power=0.2, bump=0.0)
    return [flatten_below(p) for p in parts]


def creature_mesh(res: float, kind: str, seed: int) -> MeshData:
    m = merge_meshes(creature_parts(res, kind, seed))
    return m


def creature_at(lo: int, hi: int, kind: str, seed: int) -> tuple[MeshData, float]:
    """Creature whose triangle count lies in [lo, hi]: the first res = 1 + 0.01 k
    (k >= -90) whose count is >= the middle of the range."""
    mid = (lo + hi) // 2
    tris_at = lambda r: sum(2 * max(3, round(a * r)) * max(6, round(b * r))
                            * (4 if p == "leg" else 2 if p == "horn" else 1)
                            for p, (a, b) in CREATURE_BASE.items()
                            if p != "horn" or kind == "ogre")
    res = 0.1
    while tris_at(res) < mid:
        res = round(res + 0.01, 2)
    m = creature_mesh(res, kind, seed)
    t = triangle_count(m[1])
    if not lo <= t <= hi:
        raise RuntimeError(f"creature {kind}: {t} triangles outside [{lo}, {hi}]")
    if signed_volume_np(m) <= 0.0:
        raise RuntimeError(f"creature {kind} is wound inward")
    return m, res


# ---------------------------------------------------------------------------
# Leaves, stems, plants
# ---------------------------------------------------------------------------


def leaf_strip(length: float, width: float, n_len: int, n_wid: int,
               droop: float, cup: float, twist: float = 0.0) -> MeshData:
    """Curved leaf along +X from the origin: n_len x n_wid quads, up side +Z.

    Width w(u) = width * max(sin(pi u^0.8)^0.7, 0.03); droop bends the tip
    down (z -= droop u^2), cup lifts the edges (z += cup v^2 w), twist rolls
    the leaf about its midrib linearly along it.
    """
    u = np.linspace(0.0, 1.0, n_len + 1)
    v = np.linspace(-1.0, 1.0, n_wid + 1)
    w = width * np.maximum(np.sin(math.pi * u ** 0.8) ** 0.7, 0.03)
    x = length * u[:, None] + 0.0 * v[None, :]
    yc = v[None, :] * w[:, None]
    zc = cup * w[:, None] * v[None, :] ** 2
    ang = twist * u[:, None]
    y2 = yc * np.cos(ang) - zc * np.sin(ang)
    z2 = yc * np.sin(ang) + zc * np.cos(ang) - droop * length * u[:, None] ** 2
    pts = np.stack([x, y2, z2], axis=-1).reshape(-1, 3)
    g = np.arange((n_len + 1) * (n_wid + 1)).reshape(n_len + 1, n_wid + 1)
    quads = np.stack([g[:-1, :-1], g[:-1, 1:], g[1:, 1:], g[1:, :-1]], axis=-1)
    # u x v = X x Y = +Z: counter-clockwise seen from above (front = up side)
    return pts, [4] * (n_len * n_wid), quads.reshape(-1).tolist()


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def place(m: MeshData, rot: np.ndarray, t: Sequence[float], scale: float = 1.0) -> MeshData:
    return (m[0] * scale) @ rot.T + np.asarray(t, dtype=np.float64), m[1], m[2]


def stem_curve(base, top, bend, seed_rng) -> tuple[Callable, np.ndarray]:
    base = np.asarray(base, dtype=np.float64)
    top = np.asarray(top, dtype=np.float64)
    mid1 = base + (top - base) * 0.35 + np.asarray(bend) * 0.6
    mid2 = base + (top - base) * 0.7 + np.asarray(bend)
    ctrl = np.stack([base, mid1, mid2, top])
    return polyline(ctrl), ctrl


def plant_meshes(rng: np.random.Generator, n_stems: int, height: float, spread: float,
                 leaves_per_stem: int, leaf_len: float, leaf_w: float,
                 leaf_res: tuple[int, int], stem_res: tuple[int, int],
                 stem_r: float, base_z: float = 0.0, base_spread: float = 0.05
                 ) -> tuple[MeshData, MeshData]:
    """(stems, leaves) of a plant rooted around the origin at z = base_z.

    Stems are closed thin tubes (their bases pushed below base_z and flattened
    onto it when base_z = 0); leaves are curved strips attached along each stem
    at many heights, pointing outward at varied azimuths.
    """
    stems: list[MeshData] = []
    leaves: list[MeshData] = []
    for s in range(n_stems):
        az = 2.0 * math.pi * (s + rng.uniform(-0.3, 0.3)) / n_stems
        h = height * rng.uniform(0.55, 1.0)
        d = spread * rng.uniform(0.3, 1.0)
        base = (base_spread * math.cos(az), base_spread * math.sin(az), base_z - 0.05)
        top = (d * math.cos(az), d * math.sin(az), base_z + h)
        bend = (0.25 * d * math.cos(az + 1.0), 0.25 * d * math.sin(az + 1.0), 0.0)
        curve, _ = stem_curve(base, top, bend, rng)
        prof = lerp_profile([stem_r, stem_r * 0.8, stem_r * 0.5])
        stems.append(tube(curve, rounded(prof, power=0.08), *stem_res))
        ts = np.sort(rng.uniform(0.25, 1.0, size=leaves_per_stem))
        ts[-1] = 1.0
        pos = curve(ts)
        for j, (t, p) in enumerate(zip(ts, pos)):
            laz = az + rng.uniform(-1.3, 1.3) + (math.pi if j % 2 else 0.0) * 0.6
            pitch = rng.uniform(-0.35, 0.15)  # negative: rises from the stem
            size = rng.uniform(0.7, 1.15) * (1.1 - 0.35 * t)
            leaf = leaf_strip(leaf_len * size, leaf_w * size, *leaf_res,
                              droop=rng.uniform(0.08, 0.3), cup=rng.uniform(0.1, 0.35),
                              twist=rng.uniform(-0.4, 0.4))
            leaves.append(place(leaf, rot_z(laz) @ rot_y(pitch), p))
    stems_m = flatten_below(merge_meshes(stems), base_z) if base_z == 0.0 else merge_meshes(stems)
    return stems_m, merge_meshes(leaves)


# ---------------------------------------------------------------------------
# Stage helpers
# ---------------------------------------------------------------------------


def ground(stage: Usd.Stage, half: float, center=(0.0, 0.0), color=(0.78, 0.76, 0.7)) -> int:
    cx, cy = center
    g = quad_mesh([(cx - half, cy - half, 0), (cx + half, cy - half, 0),
                   (cx + half, cy + half, 0), (cx - half, cy + half, 0)])
    make_mesh(stage, "/World/Ground", g, False,
              make_material(stage, "/World/Looks/GroundMat", color))
    return triangle_count(g[1])


def rect_light(stage: Usd.Stage, path: str, size: tuple[float, float],
               pos: Sequence[float], target: Sequence[float], irradiance: float = 1.5
               ) -> tuple[float, float]:
    """RectLight at `pos` aimed at `target`; intensity chosen so the irradiance
    at the target is about `irradiance` (intensity * area / d^2).  Returns
    (intensity, distance)."""
    w, h = size
    d = float(np.linalg.norm(np.asarray(pos, dtype=np.float64) - np.asarray(target)))
    intensity = round(irradiance * d * d / (w * h), 1)
    light = UsdLux.RectLight.Define(stage, path)
    light.CreateWidthAttr(float(w))
    light.CreateHeightAttr(float(h))
    light.CreateIntensityAttr(float(intensity))
    if abs(pos[0] - target[0]) < 1e-9 and abs(pos[1] - target[1]) < 1e-9:
        light.AddTranslateOp().Set(Gf.Vec3d(*map(float, pos)))  # identity rotation: emits -Z
        check_points_down(light.GetPrim(), (0, 0, -1), 0.999)
    else:
        light.AddTransformOp().Set(look_at_xform(pos, target, (0.0, 0.0, 1.0)))
        check_points_down(light.GetPrim(), (0, 0, -1), 0.7)
    return intensity, d


def instance(stage: Usd.Stage, path: str, proto: str, t: Sequence[float],
             rz_deg: float = 0.0, scale: float = 1.0) -> None:
    inst = UsdGeom.Xform.Define(stage, path)
    prim = inst.GetPrim()
    prim.GetReferences().AddInternalReference(Sdf.Path(proto))
    prim.SetInstanceable(True)
    inst.AddTranslateOp().Set(Gf.Vec3d(*map(float, t)))
    inst.AddRotateZOp().Set(float(rz_deg))
    inst.AddScaleOp().Set(Gf.Vec3f(float(scale), float(scale), float(scale)))


def proto_root(stage: Usd.Stage) -> None:
    root = stage.CreateClassPrim("/Prototypes")
    root.SetTypeName("Scope")


def zmin32(m: MeshData) -> float:
    return float(np.asarray(m[0], dtype=np.float32)[:, 2].min())


def bounds32(m: MeshData) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(m[0], dtype=np.float32)
    return p.min(axis=0), p.max(axis=0)


def fmt_v(v: Sequence[float]) -> str:
    return "(" + ", ".join(f"{round(float(x), 3):g}" for x in v) + ")"


CREATURE_COLOR = (0.55, 0.5, 0.38)
LEAF_COLOR = (0.25, 0.55, 0.2)
STEM_COLOR = (0.35, 0.45, 0.2)
BARK_COLOR = (0.42, 0.3, 0.2)


# ---------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------


def scene_ogre(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "ogre.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    tris = ground(stage, 8.0)
    m, res = creature_at(130000, 140000, "ogre", 1101)
    if zmin32(m) != 0.0:
        raise RuntimeError("ogre does not touch the ground")
    make_mesh(stage, "/World/Ogre", m, False,
              make_material(stage, "/World/Looks/OgreMat", CREATURE_COLOR))
    ct = triangle_count(m[1])
    tris += ct
    lo, hi = bounds32(m)
    size = (0.7, 0.7)
    pos, target = (1.8, 2.8, 5.2), (0.2, 0.0, 1.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (3.0, -7.4, 5.6), (-0.4, -1.3, 0.5), (0, 0, 1), clip=(0.1, 200.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Ogre analog (Shen, Feng & Yang ESSM, Table 1 'Ogre'): one closed creature mesh "
        f"/World/Ogre of {ct} triangles (body, neck, horned head, four legs, tail: swept tubes "
        f"displaced by smooth seeded noise, resolution factor {res:g}), bounds {fmt_v(lo)} to "
        f"{fmt_v(hi)}, so {hi[2]:.3g} tall; its four feet are flattened onto the ground z = 0 "
        "(contact shadows). Ground /World/Ground 16 x 16 at z = 0. /World/Light: RectLight "
        f"{w:g} x {h:g} ({w / hi[2]:.2g} of the creature height) at {fmt_v(pos)} aimed at "
        f"{fmt_v(target)}, intensity {inten:g}; the penumbra is contact-sharp at the feet and "
        f"wide where the head's shadow falls. Total {tris} triangles."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def scene_dinosaurs(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "dinosaurs.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    proto_root(stage)
    protos = {}
    for name, kind, seed, color in (("Sauropod", "sauropod", 2201, (0.45, 0.5, 0.35)),
                                    ("Raptor", "raptor", 2202, (0.6, 0.45, 0.3))):
        m, res = creature_at(95000, 105000, kind, seed)
        ppath = "/Prototypes/" + name
        stage.DefinePrim(ppath, "Xform")
        make_mesh(stage, ppath + "/Mesh", m, False,
                  make_material(stage, ppath + "/Looks/Skin", color))
        protos[name] = (triangle_count(m[1]), res)
    tris = ground(stage, 12.0)
    stage.DefinePrim("/World/Dinosaurs", "Xform")
    placements = [  # (name, prototype, (x, y), rotateZ deg, uniform scale)
        ("Dino0", "Sauropod", (-2.2, 1.6), 20.0, 1.1),
        ("Dino1", "Raptor", (1.8, 2.2), 160.0, 0.9),
        ("Dino2", "Sauropod", (2.4, -1.9), -35.0, 0.85),
        ("Dino3", "Raptor", (-2.0, -2.4), 75.0, 1.0),
    ]
    inst_tris = 0
    for name, proto, (x, y), rz, sc in placements:
        instance(stage, "/World/Dinosaurs/" + name, "/Prototypes/" + proto, (x, y, 0.0), rz, sc)
        inst_tris += protos[proto][0]
    tris += inst_tris
    size = (1.2, 1.2)
    pos, target = (2.5, -3.5, 8.0), (0.0, 0.0, 0.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (6.5, -8.5, 6.0), (-0.4, 0.5, 0.6), (0, 0, 1), focal=28.0,
                clip=(0.1, 300.0))
    (w, h), t_sauro, t_raptor = size, protos["Sauropod"][0], protos["Raptor"][0]
    set_doc_string(world, "wsoft:doc", (
        "Dinosaurs analog (Shen, Feng & Yang ESSM, Table 1 'Dinosaurs'): 4 instanceable Xforms "
        "/World/Dinosaurs/Dino0..3 referencing 2 creature prototypes under the class prim "
        f"/Prototypes (Sauropod {t_sauro} triangles, Raptor {t_raptor} triangles), placed with "
        "translate, rotateZ and uniform scale 0.85-1.1 (2 instances each); feet flattened onto "
        f"z = 0 (contact). Ground 24 x 24 at z = 0. /World/Light: RectLight {w:g} x {h:g} at "
        f"{fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total {tris} triangles "
        "counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": len(placements),
            "prototype_triangles": [protos["Sauropod"][0], protos["Raptor"][0]]}


def scene_plants(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "plants.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(3301)
    proto_root(stage)
    leaf_mat = make_material(stage, "/Prototypes/Looks/LeafMat", LEAF_COLOR)
    stem_mat = make_material(stage, "/Prototypes/Looks/StemMat", STEM_COLOR)
    specs = [  # n_stems, height, spread, leaves per stem, leaf length, leaf width
        (8, 1.6, 0.55, 11, 0.55, 0.16),
        (6, 1.1, 0.45, 12, 0.45, 0.2),
        (10, 2.0, 0.7, 9, 0.6, 0.14),
    ]
    proto_tris, proto_top = [], []
    for k, (ns, h, sp, lps, ll, lw) in enumerate(specs):
        stems, leaves = plant_meshes(rng, ns, h, sp, lps, ll, lw, (10, 4), (24, 8), 0.025)
        ppath = f"/Prototypes/Plant{k}"
        stage.DefinePrim(ppath, "Xform")
        make_mesh(stage, ppath + "/Stems", stems, False, stem_mat)
        make_mesh(stage, ppath + "/Leaves", leaves, True, leaf_mat)
        proto_tris.append(triangle_count(stems[1]) + triangle_count(leaves[1]))
        proto_top.append(float(max(bounds32(stems)[1][2], bounds32(leaves)[1][2])))
    tris = ground(stage, 6.0)
    stage.DefinePrim("/World/Plants", "Xform")
    n_inst, inst_tris, top = 0, 0, 0.0
    for r in range(4):
        for c in range(4):
            proto = int(rng.integers(0, len(specs)))
            jit = rng.uniform(-0.25, 0.25, size=2)
            rz = float(np.round(rng.uniform(0.0, 360.0), 2))
            sc = float(np.round(rng.uniform(0.8, 1.25), 3))
            if (r, c) == (0, 3):
                continue
            x = round((c - 1.5) * 1.1 + float(jit[0]), 3)
            y = round((r - 1.5) * 1.1 + float(jit[1]), 3)
            instance(stage, f"/World/Plants/P_{r}_{c}", f"/Prototypes/Plant{proto}",
                     (x, y, 0.0), rz, sc)
            top = max(top, proto_top[proto] * sc)
            inst_tris += proto_tris[proto]
            n_inst += 1
    tris += inst_tris
    size = (1.0, 1.0)
    pos, target = (0.8, -0.6, 6.0), (0.0, 0.0, 0.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (4.5, -5.5, 4.5), (0.0, 0.0, 0.4), (0, 0, 1), focal=28.0,
                clip=(0.1, 200.0))
    (w, h), ptris = size, ", ".join(str(t) for t in proto_tris)
    set_doc_string(world, "wsoft:doc", (
        f"Plants analog (Shen, Feng & Yang ESSM, Table 1 'Plants'): {n_inst} instanceable "
        "Xforms /World/Plants/P_r_c on a jittered 4 x 4 grid (1.1 apart, one corner empty) "
        "referencing 3 plant prototypes under the class prim /Prototypes (closed thin stem "
        "tubes plus double-sided curved leaf strips of 10 x 4 quads at many heights, so leaves "
        f"overlap in the light view at several depths; {ptris} triangles), rotateZ and uniform "
        f"scale 0.8-1.25, up to z = {top:.3g}. Ground 12 x 12 at z = 0. /World/Light: RectLight "
        f"{w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total "
        f"{tris} triangles counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": n_inst,
            "prototype_triangles": proto_tris}


def pot_mesh(radius: float, height: float, n_along: int, n_around: int) -> MeshData:
    """Closed flower pot: flat base on z = 0, flared wall, flat soil disc on top."""
    prof = lerp_profile([radius * 0.75, radius * 0.85, radius * 1.0, radius * 1.05])
    curve = polyline([(0, 0, -0.04), (0, 0, height * 0.5), (0, 0, height + 0.02)])

    def radius_fn(t, th):
        r = prof(t) * np.minimum(1.0, np.sin(math.pi * t) * 6.0) ** 0.5
        return np.broadcast_to(r, np.broadcast(t, th).shape).copy()

    m = tube(curve, radius_fn, n_along, n_around)
    p = m[0].copy()
    p[:, 2] = np.clip(p[:, 2], 0.0, height)
    return p, m[1], m[2]


def scene_fig1_plant(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "fig1_plant.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(4401)
    tris = ground(stage, 5.0)
    pot_h, pot_r = 0.35, 0.22
    pot = pot_mesh(pot_r, pot_h, 24, 48)
    stage.DefinePrim("/World/Plant", "Xform")
    make_mesh(stage, "/World/Plant/Pot", pot, False,
              make_material(stage, "/World/Looks/PotMat", (0.7, 0.4, 0.28)))
    stems, leaves = plant_meshes(rng, 13, 1.5, 0.55, 10, 0.42, 0.18, (14, 6), (48, 12), 0.018,
                                 base_z=pot_h - 0.01, base_spread=0.08)
    make_mesh(stage, "/World/Plant/Stems", stems, False,
              make_material(stage, "/World/Looks/StemMat", STEM_COLOR))
    make_mesh(stage, "/World/Plant/Leaves", leaves, True,
              make_material(stage, "/World/Looks/LeafMat", LEAF_COLOR))
    n_leaves = 13 * 10
    pt, st, lt = (triangle_count(m[1]) for m in (pot, stems, leaves))
    tris += pt + st + lt
    top = float(max(bounds32(leaves)[1][2], bounds32(stems)[1][2]))
    low = float(bounds32(leaves)[0][2])
    size = (1.6, 1.6)
    pos, target = (0.9, -0.7, 3.6), (0.0, 0.0, 0.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (2.3, -2.9, 2.2), (-0.25, 0.3, 0.45), (0, 0, 1), focal=28.0,
                clip=(0.05, 100.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Schwarz & Stamminger 2008 Fig. 1 analog: a potted plant under a large area light. "
        f"/World/Plant/Pot (closed, {pt} triangles, radius {pot_r:g}, height {pot_h:g}, flat "
        f"base on z = 0), /World/Plant/Stems (13 closed stem tubes, {st} triangles) and "
        f"/World/Plant/Leaves ({n_leaves} double-sided curved leaves of 14 x 6 quads, {lt} "
        f"triangles) at heights from {low:.3g} up to {top:.3g}. Ground 10 x 10 at z = 0. "
        f"/World/Light: RectLight {w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, "
        f"intensity {inten:g}: penumbrae are sharp where the pot meets the ground and very "
        f"wide under the highest leaves. Total {tris} triangles."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris}


def leaf_cluster(rng: np.random.Generator, n_leaves: int, radius: float, leaf_len: float,
                 leaf_w: float) -> MeshData:
    """Ball of small leaves (2 x 1 quads each) around the origin."""
    parts = []
    for _ in range(n_leaves):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        p = d * radius * rng.uniform(0.35, 1.0) ** 0.5
        p[2] *= 0.7
        leaf = leaf_strip(leaf_len, leaf_w, 2, 1, droop=rng.uniform(0.0, 0.3), cup=0.0)
        rot = rot_z(rng.uniform(0, 2 * math.pi)) @ rot_y(rng.uniform(-0.6, 0.6)) @ rot_x(
            rng.uniform(-0.6, 0.6))
        parts.append(place(leaf, rot, p))
    return merge_meshes(parts)


def branch_tree(rng: np.random.Generator, base, direction, length: float, radius: float,
                depth: int, res: tuple[int, int], out: list[MeshData],
                tips: list[tuple[np.ndarray, float]]) -> None:
    """Recursive branches: a curved tube, then 2-3 children from its upper part."""
    base = np.asarray(base, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    side = np.cross(d, [0.0, 0.0, 1.0])
    if np.linalg.norm(side) < 1e-6:
        side = np.array([1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    wob = rng.uniform(-0.12, 0.12) * length
    ctrl = [base, base + 0.35 * length * d + wob * side,
            base + 0.7 * length * d - 0.5 * wob * side + [0, 0, 0.05 * length],
            base + length * d + [0, 0, 0.08 * length]]
    curve = polyline(ctrl)
    na, nr = res
    out.append(tube(curve, rounded(lerp_profile([radius, radius * 0.8, radius * 0.55]),
                                   power=0.1), max(4, int(na * length / 1.5)), nr))
    end = curve(np.array([1.0]))[0]
    if depth == 0:
        tips.append((end, length))
        return
    n_child = 3 if depth >= 2 else int(rng.integers(2, 4))
    for c in range(n_child):
        t = rng.uniform(0.55, 0.95) if c else 0.97
        p = curve(np.array([t]))[0]
        az = math.atan2(d[1], d[0]) + 2 * math.pi * c / n_child + rng.uniform(-0.5, 0.5)
        up = rng.uniform(0.35, 0.9)
        nd = np.array([math.cos(az), math.sin(az), up]) + 0.6 * d
        branch_tree(rng, p, nd, length * rng.uniform(0.55, 0.7), radius * 0.55, depth - 1,
                    res, out, tips)
        if c and depth == 1:
            tips.append((p, 0.5 * length))


def scene_fig8_tree(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "fig8_tree.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(5501)
    proto_root(stage)
    leaf_mat = make_material(stage, "/Prototypes/Looks/LeafMat", (0.3, 0.5, 0.2))
    cl_tris = []
    for k in range(2):
        cl = leaf_cluster(rng, 140 + 30 * k, 0.45, 0.16, 0.07)
        ppath = f"/Prototypes/LeafCluster{k}"
        stage.DefinePrim(ppath, "Xform")
        make_mesh(stage, ppath + "/Leaves", cl, True, leaf_mat)
        cl_tris.append(triangle_count(cl[1]))
    tris = ground(stage, 8.0)
    parts: list[MeshData] = []
    tips: list[tuple[np.ndarray, float]] = []
    trunk_h = 2.0
    trunk_curve = polyline([(0, 0, -0.1), (0.05, 0.02, 0.8), (-0.05, 0.05, 1.5),
                            (0.0, 0.0, trunk_h)])
    trunk_prof = lerp_profile([0.32, 0.2, 0.17, 0.15])
    parts.append(tube(trunk_curve, rounded(trunk_prof, power=0.05, bump=0.08, seed=5502,
                                           fmax=6.0, kmax=6), 60, 24))
    top = trunk_curve(np.array([1.0]))[0]
    for c in range(4):
        az = 2 * math.pi * c / 4 + 0.4
        branch_tree(rng, top - [0, 0, 0.15 * c], (math.cos(az), math.sin(az), 0.9), 1.4,
                    0.12, 2, (24, 10), parts, tips)
    wood = flatten_below(merge_meshes(parts))
    stage.DefinePrim("/World/Tree", "Xform")
    make_mesh(stage, "/World/Tree/Wood", wood, False,
              make_material(stage, "/World/Looks/BarkMat", BARK_COLOR))
    wood_tris = triangle_count(wood[1])
    tris += wood_tris
    stage.DefinePrim("/World/Tree/Foliage", "Xform")
    for i, (p, ln) in enumerate(tips):
        k = i % 2
        sc = float(np.round(0.8 + 0.6 * min(ln, 1.0), 3))
        instance(stage, f"/World/Tree/Foliage/C{i:03d}", f"/Prototypes/LeafCluster{k}",
                 np.round(p, 4), float(np.round(rng.uniform(0, 360), 2)), sc)
        tris += cl_tris[k]
    hi = float(max(p[2] for p, _ in tips)) + 0.5
    size = (1.5, 1.5)
    pos, target = (2.0, -1.5, 7.0), (0.0, 0.0, 0.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (5.0, -6.5, 3.8), (-0.6, 0.6, 1.3), (0, 0, 1), focal=26.0,
                clip=(0.1, 200.0))
    (w, h), ctris = size, ", ".join(str(t) for t in cl_tris)
    set_doc_string(world, "wsoft:doc", (
        f"Schwarz & Stamminger 2008 Fig. 8 analog: a tree. /World/Tree/Wood (trunk {trunk_h:g} "
        "tall with a flat base on z = 0, three levels of curved branches; one closed-tube mesh, "
        f"{wood_tris} triangles) and {len(tips)} instanceable leaf clusters "
        "/World/Tree/Foliage/Cnnn referencing 2 prototypes under the class prim /Prototypes "
        f"({ctris} triangles: balls of small double-sided leaves of 2 quads), up to about "
        f"z = {hi:.3g}. Ground 16 x 16 at z = 0. /World/Light: RectLight {w:g} x {h:g} at "
        f"{fmt_v(pos)} aimed at {fmt_v(target)}, intensity {inten:g}. Total {tris} triangles "
        "counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": len(tips),
            "prototype_triangles": cl_tris}


def frond_mesh(rng: np.random.Generator, length: float, n_leaflets: int) -> MeshData:
    """Palm frond along +X from the origin: drooping rachis tube plus leaflets on both
    sides hanging down and outward."""
    droop = lambda u: 0.35 * length * u - 0.75 * length * u * u
    ctrl = [(length * u, 0.0, droop(u)) for u in np.linspace(0.0, 1.0, 6)]
    curve = polyline(ctrl)
    parts = [tube(curve, rounded(lerp_profile([0.04, 0.025, 0.01]), power=0.1), 30, 6)]
    us = np.linspace(0.08, 0.98, n_leaflets)
    pts = curve(us)
    for u, p in zip(us, pts):
        ll = 0.55 * length * (0.25 + math.sin(math.pi * min(u * 1.1, 1.0)) * 0.75) / 2.2
        for side in (1.0, -1.0):
            leaf = leaf_strip(ll, 0.035, 5, 1, droop=0.25, cup=0.0)
            rot = rot_z(side * (math.pi / 2 - 0.6)) @ rot_x(side * -0.5) @ rot_y(
                rng.uniform(0.2, 0.5))
            parts.append(place(leaf, rot, p))
    return merge_meshes(parts)


FROND_LEAFLETS = 44  # per side
DINO_AT, DINO_RZ = (-1.1, -0.9, 0.0), 10.0


def scene_palm_dino(out_dir: str) -> dict[str, object]:
    path = os.path.join(out_dir, "palm_dino.usdc")
    stage = new_stage(path, "Z")
    world = stage.GetPrimAtPath("/World")
    rng = np.random.default_rng(6601)
    proto_root(stage)
    frond = frond_mesh(rng, 2.6, FROND_LEAFLETS)
    stage.DefinePrim("/Prototypes/Frond", "Xform")
    make_mesh(stage, "/Prototypes/Frond/Mesh", frond, True,
              make_material(stage, "/Prototypes/Frond/Looks/FrondMat", (0.3, 0.55, 0.2)))
    frond_tris = triangle_count(frond[1])
    tris = ground(stage, 9.0)
    # palm trunk: curved, ringed, flat base on z = 0
    crown = np.array([0.9, 0.4, 4.6])
    trunk_curve = polyline([(0, 0, -0.1), (0.1, 0.05, 1.5), (0.45, 0.2, 3.2), tuple(crown)])

    def trunk_r(t, th):
        r = (0.24 - 0.08 * t) * (1.0 + 0.06 * np.sin(2 * math.pi * 28 * t)) + 0.12 * np.maximum(
            0.0, 0.08 - t)
        r = r * np.minimum(1.0, np.sin(math.pi * t) * 15.0) ** 0.5
        return np.broadcast_to(r, np.broadcast(t, th).shape).copy()

    trunk = flatten_below(tube(trunk_curve, trunk_r, 140, 24))
    stage.DefinePrim("/World/Palm", "Xform")
    make_mesh(stage, "/World/Palm/Trunk", trunk, False,
              make_material(stage, "/World/Looks/BarkMat", BARK_COLOR))
    trunk_tris = triangle_count(trunk[1])
    tris += trunk_tris
    stage.DefinePrim("/World/Palm/Fronds", "Xform")
    n_fronds = 14
    for i in range(n_fronds):
        az = 360.0 * i / n_fronds + float(np.round(rng.uniform(-8, 8), 2))
        sc = float(np.round(rng.uniform(0.85, 1.15), 3))
        instance(stage, f"/World/Palm/Fronds/F{i:02d}", "/Prototypes/Frond",
                 np.round(crown - [0, 0, 0.05 * (i % 3)], 4), az, sc)
        tris += frond_tris
    dino, _res = creature_at(25000, 35000, "sauropod", 6602)
    dino_tris = triangle_count(dino[1])
    dpath = "/World/Dino"
    dm = make_mesh(stage, dpath, dino, False,
                   make_material(stage, "/World/Looks/DinoMat", (0.5, 0.48, 0.36)))
    dm.AddTranslateOp().Set(Gf.Vec3d(*DINO_AT))
    dm.AddRotateZOp().Set(DINO_RZ)
    tris += dino_tris
    size = (1.4, 1.4)
    pos, target = (1.8, -1.2, 9.5), (0.3, 0.3, 0.0)
    inten, _ = rect_light(stage, "/World/Light", size, pos, target)
    make_camera(stage, (5.5, -8.0, 4.5), (-0.3, 0.6, 1.8), (0, 0, 1), focal=26.0,
                clip=(0.1, 200.0))
    w, h = size
    set_doc_string(world, "wsoft:doc", (
        "Schwarz & Stamminger 2008 Fig. 10 analog: a palm over a dinosaur. /World/Palm/Trunk "
        f"(curved ringed closed tube, flat base on z = 0, crown at {fmt_v(crown)}, {trunk_tris} "
        f"triangles), {n_fronds} instanceable fronds /World/Palm/Fronds/Fnn referencing the "
        f"class prototype /Prototypes/Frond ({frond_tris} triangles: drooping rachis tube plus "
        f"{2 * FROND_LEAFLETS} double-sided leaflets, scale 0.85-1.15), and /World/Dino (closed "
        f"sauropod creature, {dino_tris} triangles, translate {fmt_v(DINO_AT)}, rotateZ "
        f"{DINO_RZ:g}, feet flattened onto z = 0). Ground 18 x 18 at z = 0. /World/Light: "
        f"RectLight {w:g} x {h:g} at {fmt_v(pos)} aimed at {fmt_v(target)}, intensity "
        f"{inten:g}. Total {tris} triangles counting every instance."))
    stage.GetRootLayer().Save()
    return {"file": path, "triangles": tris, "instances": n_fronds,
            "prototype_triangles": [frond_tris]}


ORGANIC_SCENES = {
    "ogre": scene_ogre,
    "plants": scene_plants,
    "dinosaurs": scene_dinosaurs,
    "fig1_plant": scene_fig1_plant,
    "fig8_tree": scene_fig8_tree,
    "palm_dino": scene_palm_dino,
}
