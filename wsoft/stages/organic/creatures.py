"""Creatures: a quadruped's body, neck, head, four legs, tail (and horns) as closed swept tubes,
Z up, facing +X, feet flattened onto z = 0."""

from __future__ import annotations

import numpy as np

from wsoft.stages.mesh import MeshData, flatten_below, merge_meshes, signed_volume, triangle_count
from wsoft.stages.organic.tubes import lerp_profile, polyline, rounded, tube


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
    """The creature's parts in one mesh (each part closed; they overlap inside it)."""
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
    if signed_volume(m) <= 0.0:
        raise RuntimeError(f"creature {kind} is wound inward")
    return m, res
