"""What the object-based techniques (``dcs``, ``pwedge``) share: a light's casters split into opaque
and perforated (cutout) triangles, a BVH over the opaque ones that counts the triangles a segment
crosses, and the perforated triangles' soft textured shadow volumes (Forest et al. 2009, §2 and §6)
binned by light-space cell for the receivers (:mod:`wsoft.accel.dcs_bins`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.dcs_bins import build_bins, grid_view
from wsoft.lightspace.light import LightGPU, light_bound, reached_receivers
from wsoft.accel.stsv import planes_t, triangle_volumes
from wsoft.lightspace.fit import fit_light_view
from wsoft.parallel import launch_chunked
from wsoft.scene.rays import ray_triangle
from wsoft.scene.types import LIGHT_DISK, LIGHT_RECT


@wp.func
def count_crossings(bvh: wp.uint64, tri_pts: wp.array[wp.vec3], o: wp.vec3, d: wp.vec3, tm: float) -> int:
    """Opaque triangles (``tri_pts[3k:3k+3]``, item ``k`` of ``bvh``) the segment ``o + t d``,
    ``t in (0, tm)``, crosses (Warp's watertight ray-triangle test, as the reference's any-hit)."""
    n = int(0)
    q = wp.bvh_query_ray(bvh, o, d)
    k = int(0)
    while wp.bvh_query_next(q, k, tm):
        h = ray_triangle(o, d, tri_pts[3 * k], tri_pts[3 * k + 1], tri_pts[3 * k + 2])
        if h[0] != 0.0 and h[1] > 0.0 and h[1] < tm:
            n += 1
    return n


MAX_PARTS = 8  # distinct parts count_parts tells apart; more are counted once per crossing
parts_t = wp.types.vector(length=MAX_PARTS, dtype=wp.int32)


@wp.func
def count_parts(bvh: wp.uint64, tri_pts: wp.array[wp.vec3], part: wp.array[wp.int32], o: wp.vec3, d: wp.vec3, tm: float) -> int:
    """How many distinct parts (``part[k]`` of opaque triangle ``k``: its connected piece of mesh,
    :func:`~wsoft.scene.adjacency.triangle_parts`) the segment ``o + t d``, ``t in (0, tm)``,
    crosses: a closed box crossed through two faces is one occluder over the light's point, two
    boxes one behind the other are two (the stencil count of shadow volumes). The first
    :data:`MAX_PARTS` parts are told apart; past them each crossing counts."""
    seen = parts_t()
    n = int(0)
    q = wp.bvh_query_ray(bvh, o, d)
    k = int(0)
    while wp.bvh_query_next(q, k, tm):
        h = ray_triangle(o, d, tri_pts[3 * k], tri_pts[3 * k + 1], tri_pts[3 * k + 2])
        if h[0] != 0.0 and h[1] > 0.0 and h[1] < tm:
            pk = part[k]
            new = int(1)
            for j in range(MAX_PARTS):
                if j < n and seen[j] == pk:
                    new = 0
            if new != 0:
                if n < MAX_PARTS:
                    seen[n] = pk
                n += 1
    return n


@wp.func
def in_wedge(ne: wp.vec3, nn: float, ball: wp.vec4, distant: int, o: wp.vec3) -> bool:
    """Is ``o`` inside the wedge of an edge whose plane through ``o`` has the normal ``ne``
    (``nn = |ne|^2``): does that plane cut the light's bound (``ball``: centre and radius, a
    distant light's cone as the ball it cuts at unit distance, ``distant``)?"""
    hb = wp.dot(ne, wp.vec3(ball[0], ball[1], ball[2]))
    if distant == 0:
        hb = wp.dot(ne, wp.vec3(ball[0], ball[1], ball[2]) - o)
    return not (nn == 0.0 or hb * hb > ball[3] * ball[3] * nn * 1.0001)


@wp.func
def side(x: float) -> int:
    """The sign of ``x`` as an int (0 at 0)."""
    if x > 0.0:
        return 1
    if x < 0.0:
        return -1
    return 0


@wp.kernel
def build_triangle_volumes(
    offset: int,
    pts: wp.array[wp.vec3],
    light: LightGPU,
    # outputs
    planes: wp.array2d[planes_t],
):
    """Both soft textured shadow volumes of perforated triangle ``i`` (an empty one where its
    side's half-space holds no part of the light, §6)."""
    i = wp.tid() + offset
    lit, front, back = triangle_volumes(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2], light)
    planes[i, 0] = front
    planes[i, 1] = back


def triangle_masks(scene, light) -> tuple[np.ndarray, np.ndarray]:
    """(opaque, perforated) [T] bool: the triangles that cast ``light``'s shadow (its
    ``collection:shadowLink`` applied), split by whether their material is a cutout. A rect or
    disk light emits on one side of its plane: perforated triangles wholly behind it can block no
    shadow ray (both ends of every ray lie in front), so they are left out and a light whose view
    holds none plans no STSV pass. (Opaque triangles are kept whole: dropping part of a mesh would
    open its adjacency and make false silhouette edges.)"""
    cutout = np.array([m.is_cutout for m in scene.materials], bool)[scene.tri_material] if scene.triangle_count else np.zeros(0, bool)
    cast = scene.casting_mask(light)
    cast = np.ones(scene.triangle_count, bool) if cast is None else np.asarray(cast, bool)
    perforated = cast & cutout
    if light.kind in (LIGHT_RECT, LIGHT_DISK) and perforated.any():
        ids = np.flatnonzero(perforated)
        h = (scene.points[scene.triangles[ids]] - np.asarray(light.position, np.float64)) @ np.asarray(light.frame[:, 2], np.float64)
        perforated[ids[~(h < 0.0).any(axis=1)]] = False
    return cast & ~cutout, perforated


def opaque_bvh(scene, opaque: np.ndarray, device) -> dict:
    """The opaque casters on the device: ``tri_pts`` (3 corners per triangle), ``bvh`` (a
    ``wp.Bvh`` over their boxes, None when there are none) and ``has_opaque``."""
    ids = np.flatnonzero(opaque)
    if not len(ids):
        return {"tri_pts": wp.zeros(3, dtype=wp.vec3, device=device), "bvh": None, "has_opaque": 0}
    tp = scene.points[scene.triangles[ids]].astype(np.float32)  # [n, 3, 3]
    bvh = wp.Bvh(wp.array(tp.min(axis=1), dtype=wp.vec3, device=device), wp.array(tp.max(axis=1), dtype=wp.vec3, device=device))
    return {"tri_pts": wp.array(tp.reshape(-1, 3), dtype=wp.vec3, device=device), "bvh": bvh, "has_opaque": 1}


def wedge_spread(light) -> tuple[float, float]:
    """(radius, tan of the half angle) by which a caster's footprint widens in the bins: a local
    light's enclosing-ball radius, a distant light's cone."""
    _, r, distant = light_bound(light)
    return (0.0, math.tan(math.radians(0.5 * light.angle_deg))) if distant else (r, 0.0)


def perforated_volumes(scene, perforated: np.ndarray, L: LightGPU, light, view, zr_max: float, device) -> tuple[dict, dict]:
    """The soft textured shadow volumes of the perforated casters and their bins in ``view``
    (:func:`~wsoft.accel.dcs_bins.build_bins`): (counters, device data ``tbins``, ``stri`` (scene
    triangle ids), ``planes`` [n, 2], ``cut_pts``)."""
    ids = np.flatnonzero(perforated).astype(np.int32)
    tp = scene.points[scene.triangles[ids]].astype(np.float32)
    cut_pts = wp.array(tp.reshape(-1, 3), dtype=wp.vec3, device=device)
    planes = wp.empty((len(ids), 2), dtype=planes_t, device=device)
    launch_chunked(build_triangle_volumes, len(ids), inputs=[cut_pts, L], outputs=[planes], device=device, min_chunk=1024)
    radius, tan_a = wedge_spread(light)
    tbins = build_bins(view, tp, radius, tan_a, zr_max, device)
    counters = {"perforated_triangles": int(len(ids)), "stsv_bin_pairs": tbins.pairs, "stsv_grid_size": tbins.view.width,
                "stsv_grid_bytes": tbins.bytes}
    data = {"tbins": tbins, "stri": wp.array(ids, dtype=wp.int32, device=device), "planes": planes, "cut_pts": cut_pts}
    return counters, data


def receiver_grid(light, gb, scene, size: int):
    """The light-space grid the bins use: a light view fitted to the G-buffer's receivers, resampled
    to ``size x size`` cells, and the receivers' farthest depth in it (slightly widened): (view, zr_max)."""
    prim = gb.prim.numpy()
    rec = reached_receivers(light, gb.pos.numpy()[prim >= 0])  # a shaped light: the receivers its cone reaches
    lo, hi = scene.bounds
    view = fit_light_view(light, rec, lo, hi, max(256, size))
    grid = grid_view(view, size)
    zr = grid.to_view(rec)[:, 2] if len(rec) else np.zeros(1)
    return grid, float(zr.max()) * (1.0 + 1e-5) + 1e-6 * grid.extent


@dataclass
class Prep:
    """What a later pass of one light reads, built by the edge and STSV passes of ``dcs`` and
    ``pwedge``: the grid's view, the receivers' farthest view depth, counters and the device data
    (arrays, bins, a BVH)."""

    view: object
    zr_max: float
    counters: dict
    data: dict

    def arrays(self) -> dict[str, wp.array]:
        """The device arrays it holds, by name (the frame graph's memory report)."""
        out = {}
        for k, v in self.data.items():
            if isinstance(v, wp.array):
                out[k] = v
            elif hasattr(v, "gpu") and hasattr(v.gpu, "items"):
                out[k + ".start"] = v.gpu.start
                out[k + ".items"] = v.gpu.items
        return out


def edge_pass(ctx, light, gb, scene, opaque: np.ndarray, perforated: np.ndarray, size: int, corners: np.ndarray, pass_name: str,
              arrays: dict, counters: dict) -> Prep:
    """What an edge pass of ``dcs`` or ``pwedge`` builds for one light: the receivers' grid
    (:func:`receiver_grid`), the edges (``corners`` [E, 2, 3]) binned in it, the opaque casters'
    BVH (:func:`opaque_bvh`) beside the technique's own ``arrays``, its ``counters`` with the bins'
    sizes, and (under ``collection:shadowLink``) the casting triangles in ``pass_name``'s counters."""
    grid, zr_max = receiver_grid(light, gb, scene, size)
    radius, tan_a = wedge_spread(light)
    ebins = build_bins(grid, corners, radius, tan_a, zr_max, ctx.device)
    data = {"ebins": ebins} | arrays | opaque_bvh(scene, opaque, ctx.device)
    if scene.casting_mask(light) is not None:  # collection:shadowLink: edges, BVH and volumes of these alone
        ctx.ctx.pass_counters(pass_name)["casting_triangles"] = int(opaque.sum() + perforated.sum())
    counters = counters | {"edge_bin_pairs": ebins.pairs, "edges_in_every_cell": ebins.whole, "grid_size": ebins.view.width,
                           "grid_bytes": ebins.bytes}
    return Prep(view=grid, zr_max=zr_max, counters=counters, data=data)
