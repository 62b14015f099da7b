"""Plants: curved leaf strips, stems, pots, leaf clusters, branching trees and palm fronds."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from wsoft.stages.mesh import MeshData, flatten_below, merge_meshes, place, rot_x, rot_y, rot_z
from wsoft.stages.organic.tubes import lerp_profile, polyline, rounded, tube


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


def stem_curve(base, top, bend, seed_rng) -> tuple[Callable, np.ndarray]:
    """A stem from ``base`` to ``top`` bowed by ``bend``: its curve and its 4 control points."""
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
