"""Does Warp's BVH have the layout :mod:`wsoft.reference.packets` reads?

The packets read Warp's private node arrays (``warp/native/bvh.h``) through a few
``wp.func_native`` readers; a Warp that lays its BVH out differently would give them wrong nodes,
or code that does not compile. :func:`bvh_layout_error` finds out once per device and process: it
builds a mesh of 48 scattered triangles, walks its BVH with the readers
(:func:`walk_known_bvh`: every triangle once in the leaves, every box holding what lies below
it, every node reached) and compares 96 rays' nearest hits found by that walk with Warp's public
``wp.mesh_query_ray`` (:func:`nearest_hits_both_ways`). On a mismatch it warns once and the
reference traces one ray at a time with ``mesh_query_ray_anyhit`` (slower, the same answer).

These kernels and every kernel that reads the BVH compile in one Warp module,
:data:`PACKETS_MODULE`: a layout the readers cannot compile against fails that module alone.
"""

from __future__ import annotations

import warnings

import numpy as np
import warp as wp

from wsoft.reference.packets import (
    STACK,
    bvh_item_count,
    bvh_left,
    bvh_lower,
    bvh_node_count,
    bvh_primitive,
    bvh_right,
    bvh_root,
    bvh_upper,
    ray_reaches_box,
    stack_i,
)
from wsoft.scene.rays import ray_triangle

PACKETS_MODULE = "wsoft.reference.packets"  # the Warp module of every kernel that reads Warp's BVH


@wp.kernel(module=PACKETS_MODULE)
def walk_known_bvh(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    items: int,
    # outputs
    seen: wp.array[wp.int32],
    info: wp.array[wp.int32],
):
    """Walk the BVH of a mesh of ``items`` triangles with the node readers (one thread; every index
    bounds-checked before it is read): each triangle's count in the leaves (``seen``), and
    ``info`` = (nodes reached, the node count Warp keeps, faults: a box not holding what lies below
    it, an index out of range, more nodes than a binary tree of ``items`` leaves has)."""
    nodes = bvh_node_count(mesh)
    limit = 2 * items
    reached = int(0)
    faults = int(0)
    stack = stack_i()
    sp = int(0)
    if bvh_item_count(mesh) != items or nodes <= 0 or nodes > limit:
        faults += 1
    else:
        stack[0] = bvh_root(mesh)
        sp = 1
    while sp > 0 and faults == 0:
        sp -= 1
        node = stack[sp]
        if node < 0 or node >= nodes or reached >= limit:
            faults += 1
            continue
        reached += 1
        lo = bvh_lower(mesh, node) - wp.vec3(1.0e-5)
        hi = bvh_upper(mesh, node) + wp.vec3(1.0e-5)
        left = bvh_left(mesh, node)
        right = bvh_right(mesh, node)
        if left < 0:
            first = -1 - left
            if first >= right or right > items:
                faults += 1
                continue
            for slot in range(first, right):
                prim = bvh_primitive(mesh, slot)
                if prim < 0 or prim >= items:
                    faults += 1
                    continue
                seen[prim] += 1
                for k in range(3):
                    c = points[indices[3 * prim + k]]
                    if wp.min(c - lo) < 0.0 or wp.min(hi - c) < 0.0:
                        faults += 1
        else:
            if sp + 2 > STACK or left >= nodes or right < 0 or right >= nodes:
                faults += 1
                continue
            for child in range(2):
                ch = wp.where(child == 0, left, right)
                if wp.min(bvh_lower(mesh, ch) - lo) < 0.0 or wp.min(hi - bvh_upper(mesh, ch)) < 0.0:
                    faults += 1
            stack[sp] = left
            stack[sp + 1] = right
            sp += 2
    info[0] = reached
    info[1] = nodes
    info[2] = faults


@wp.kernel(module=PACKETS_MODULE)
def nearest_hits_both_ways(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    # outputs
    walked: wp.array[wp.vec2],
    queried: wp.array[wp.vec2],
):
    """Each ray's nearest hit as (face, t), or (-1, 0): found by walking the BVH with the node
    readers and testing its leaves' triangles, and by Warp's public ``mesh_query_ray``."""
    r = wp.tid()
    o = origin[r]
    d = dir[r]
    best_t = float(1.0e30)
    best_f = int(-1)
    nodes = bvh_node_count(mesh)
    stack = stack_i()
    stack[0] = bvh_root(mesh)
    sp = int(1)
    steps = int(0)
    while sp > 0 and steps < 4 * nodes:
        steps += 1
        sp -= 1
        node = stack[sp]
        pad = wp.vec3(1.0e-4)
        if not ray_reaches_box(o, d, best_t, bvh_lower(mesh, node) - pad, bvh_upper(mesh, node) + pad):
            continue
        left = bvh_left(mesh, node)
        right = bvh_right(mesh, node)
        if left < 0:
            for slot in range(-1 - left, right):
                prim = bvh_primitive(mesh, slot)
                h = ray_triangle(o, d, points[indices[3 * prim]], points[indices[3 * prim + 1]], points[indices[3 * prim + 2]])
                if h[0] != 0.0 and h[1] < best_t:
                    best_t = h[1]
                    best_f = prim
        elif sp + 2 <= STACK:
            stack[sp] = left
            stack[sp + 1] = right
            sp += 2
    walked[r] = wp.vec2(float(best_f), wp.where(best_f >= 0, best_t, 0.0))
    q = wp.mesh_query_ray(mesh, o, d, 1.0e30)
    queried[r] = wp.vec2(wp.where(q.result, float(q.face), -1.0), wp.where(q.result, q.t, 0.0))


def layout_mismatch(device: str) -> str | None:
    """Why the node readers above do not read Warp's BVH as it is (None: they do). A mesh of 48
    scattered triangles is built and walked: every triangle must appear once in the leaves, every
    box hold what lies below it, every node be reached, and 96 rays' nearest hits found by the walk
    must be ``wp.mesh_query_ray``'s (same triangle, same ``t``). A layout the readers cannot compile
    against counts as a mismatch."""
    rng = np.random.default_rng(7)
    items = 48
    centres = rng.uniform(-4.0, 4.0, (items, 1, 3))
    tris = (centres + rng.uniform(-0.6, 0.6, (items, 3, 3))).astype(np.float32)
    try:
        points = wp.array(tris.reshape(-1, 3), dtype=wp.vec3, device=device)
        indices = wp.array(np.arange(3 * items, dtype=np.int32), dtype=wp.int32, device=device)
        mesh = wp.Mesh(points=points, indices=indices)
        seen = wp.zeros(items, dtype=wp.int32, device=device)
        info = wp.zeros(3, dtype=wp.int32, device=device)
        wp.launch(walk_known_bvh, 1, inputs=[mesh.id, points, indices, items], outputs=[seen, info], device=device)
        reached, nodes, faults = (int(v) for v in info.numpy())
        if faults or reached != nodes or not np.all(seen.numpy() == 1):
            return f"walking a known mesh: {faults} faults, {reached} of {nodes} nodes reached, triangles seen {seen.numpy().tolist()}"
        targets = np.einsum("rk,rkc->rc", rng.dirichlet((1.0, 1.0, 1.0), 96), tris[np.arange(96) % items])  # a point on each
        o = rng.uniform(-12.0, 12.0, (96, 3))
        d = targets - o
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        walked = wp.empty(96, dtype=wp.vec2, device=device)
        queried = wp.empty(96, dtype=wp.vec2, device=device)
        wp.launch(nearest_hits_both_ways, 96,
                  inputs=[mesh.id, points, indices, wp.array(o.astype(np.float32), dtype=wp.vec3, device=device),
                          wp.array(d.astype(np.float32), dtype=wp.vec3, device=device)],
                  outputs=[walked, queried], device=device)
        a, b = walked.numpy(), queried.numpy()
    except Exception as e:  # noqa: BLE001 (a field renamed or retyped: the readers do not compile)
        return f"the node readers do not compile against it ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})"
    hits = int((b[:, 0] >= 0).sum())
    if not (np.array_equal(a[:, 0], b[:, 0]) and np.allclose(a[:, 1], b[:, 1], rtol=1e-5, atol=1e-6)) or hits < 48:
        return f"nearest hits of 96 rays differ from wp.mesh_query_ray's ({hits} hit)"
    return None


_layout_checked: dict[str, str | None] = {}


def bvh_layout_error(device: str) -> str | None:
    """:func:`layout_mismatch` on ``device``, checked once per device per process; a mismatch is
    warned about once (the reference then traces one ray at a time: slower, the same answer)."""
    key = str(device).split(":")[0] if str(device).startswith("cpu") else str(device)
    if key not in _layout_checked:
        why = layout_mismatch(device)
        _layout_checked[key] = why
        if why is not None:
            warnings.warn(f"Warp {wp.__version__}'s BVH layout is not the one wsoft.reference.packets reads ({why}): "
                          "the reference traces one ray at a time (slower, the same answer)", RuntimeWarning, stacklevel=2)
    return _layout_checked[key]
