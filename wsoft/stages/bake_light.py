"""Baked lighting for static meshes: per-vertex irradiance with shadows from static boxes.

What ``lightmapped_bridge`` carries in ``primvars:wsoft:bakedLight`` (``usd_scenes/README.md``,
"Baked lighting"), computed with numpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wsoft.stages.mesh import MeshData, face_normals


def segments_blocked(p0: np.ndarray, p1: np.ndarray,
                     boxes: Sequence[tuple[Sequence[float], Sequence[float]]]) -> np.ndarray:
    """(N,) bool: does the segment p0[i] -> p1[i] meet any axis-aligned box?

    Slab test with the segment parameterised t in [0, 1]; a segment that
    starts inside a box counts as blocked.
    """
    d = p1 - p0
    blocked = np.zeros(len(p0), dtype=bool)
    par = d == 0.0
    safe = np.where(par, 1.0, d)
    for lo, hi in boxes:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        ta = (lo - p0) / safe
        tb = (hi - p0) / safe
        inside = (p0 >= lo) & (p0 <= hi)
        tmin = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
        tmax = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
        tnear = np.max(tmin, axis=1)
        tfar = np.min(tmax, axis=1)
        blocked |= (tnear <= tfar) & (tfar > 0.0) & (tnear < 1.0)
    return blocked


BAKE_AMBIENT = 0.05
BAKE_OFFSET = 1e-3  # start of the shadow segment, along the face normal
BAKE_SUN_FAR = 1000.0  # length of the shadow segment toward a distant light


def bake_vertex_irradiance(m: MeshData, lights: Sequence[dict[str, object]],
                           boxes: Sequence[tuple[Sequence[float], Sequence[float]]]) -> np.ndarray:
    """Per-vertex RGB irradiance (V, 3) of a static mesh.

    For every face corner, with the face normal n:
      E = sum over lights of color * weight * max(0, n.l) * falloff * visibility,
    where a "distant" light has weight = intensity and falloff 1, and a
    "sphere" light is a point at its centre with weight = intensity * pi * r^2
    and falloff 1 / d^2.  Visibility is a segment-vs-box test against the
    static boxes only.  A vertex gets the mean over its face corners, plus the
    constant BAKE_AMBIENT.  Values are rounded to 4 decimals.
    """
    pts = np.asarray(m[0], dtype=np.float32).astype(np.float64)  # as written
    counts, idx = m[1], m[2]
    fn = face_normals((pts, counts, idx))
    corner_v = np.asarray(idx, dtype=np.int64)
    corner_n = np.repeat(fn, np.asarray(counts, dtype=np.int64), axis=0)
    p = pts[corner_v]
    start = p + BAKE_OFFSET * corner_n
    e = np.zeros((len(p), 3), dtype=np.float64)
    for light in lights:
        color = np.asarray(light["color"], dtype=np.float64)
        if light["kind"] == "distant":
            to_l = np.broadcast_to(np.asarray(light["to_light"], dtype=np.float64), p.shape)
            end = start + BAKE_SUN_FAR * to_l
            falloff = np.ones(len(p))
            weight = float(light["intensity"])
        else:
            c = np.asarray(light["position"], dtype=np.float64)
            dv = c - p
            d2 = dv[:, 0] * dv[:, 0] + dv[:, 1] * dv[:, 1] + dv[:, 2] * dv[:, 2]
            to_l = dv / np.sqrt(d2)[:, None]
            end = np.broadcast_to(c, p.shape)
            falloff = 1.0 / d2
            r = float(light["radius"])
            weight = float(light["intensity"]) * math.pi * r * r
        cos = (corner_n[:, 0] * to_l[:, 0] + corner_n[:, 1] * to_l[:, 1]
               + corner_n[:, 2] * to_l[:, 2])
        vis = ~segments_blocked(start, end, boxes)
        term = weight * np.maximum(cos, 0.0) * falloff * vis
        e += term[:, None] * color[None, :]
    total = np.zeros((len(pts), 3), dtype=np.float64)
    np.add.at(total, corner_v, e)
    n_corners = np.bincount(corner_v, minlength=len(pts)).astype(np.float64)
    out = total / np.maximum(n_corners, 1.0)[:, None] + BAKE_AMBIENT
    return np.round(out, 4)
