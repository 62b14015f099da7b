"""Shadow rays that share an origin, traced through the scene's BVH together (a packet).

All the light samples of one receiver start at the same point and fan out over the light: a
narrow frustum. :func:`trace_packet` walks the BVH once for up to :data:`PACKET` such rays,
testing each node against the packet's interval bounds (the range of the rays' direction
components per axis, conservative: a node no ray can reach is skipped; one some ray might
reach is visited) and each reached leaf's triangles against the packet's rays still unblocked
whose own segment meets the leaf's box (a per-ray slab test on a slightly padded box: the
packet's bounds reach many leaves that most of its rays miss), stopping when all are blocked.
Alpha-tested cutouts decide at the exact hit, as :func:`~wsoft.scene.surfaces.occluded` does.

The BVH is Warp's own (``wp.Mesh``'s, built once per scene): Warp has no kernel-level access to
its nodes, so a few ``wp.func_native`` one-liners read them (:func:`bvh_root`, :func:`bvh_lower`
..., the layout of ``warp/native/bvh.h``: packed node halves, leaves flagged in the lower half,
primitive ranges in ``primitive_indices``; :mod:`wsoft.reference.layout` checks once per process
that the Warp installed still lays its BVH out so, else the reference traces ray by ray), and the
ray-triangle test is Warp's own
(:func:`~wsoft.scene.rays.ray_triangle`, the ``intersect_ray_tri_woop`` that
``mesh_query_ray_anyhit`` calls), so a packet's answer is the per-ray answer bit for bit: the same
triangles hit at the same ``t``. One kind of exception found (``tests/test_packets.py``), in
which the packet agrees with the brute force over every triangle and the per-ray walk does not:
a ray through the shared edge of two triangles hit at the same ``t``, whose boxes Warp's per-ray
walk drops (city, fence_mesh: one ray each). Past a cutout's hole the per-ray walk goes on from a
few ulps beyond the hole's plane (:func:`~wsoft.scene.offsets.step_past`), so it meets what the
packet meets behind it.

Warp's per-ray any-hit gives up (reports *unblocked*) when its traversal stack of 32 pending
nodes is full. :func:`pack_bvh` walks the whole tree once with the packets' own stack of
:data:`STACK` and refuses a tree that would overflow it (the reference then traces ray by ray and
says so), so a packet's traversal never drops a node.

The repacked BVH (:class:`PackedBVH`) keeps Warp's tree (same boxes, same leaves) in a layout
for this walk: each inner node is one 64-byte record holding both children's boxes, records in
depth-first order, and the triangles' corners copied in leaf order.
"""

from __future__ import annotations

import warp as wp

from wsoft.scene.rays import ray_triangle
from wsoft.scene.surfaces import Surfaces, occluded, surface_present

PACKET = 32  # rays a packet holds (one 32-bit word of a mask)
STACK = 64  # BVH nodes a packet's traversal keeps pending
WORK_PER_RAY = 12  # a packet gives up past this many node visits and ray-triangle tests per ray (ray-box tests count half)

packet_f = wp.types.vector(length=PACKET, dtype=float)
stack_i = wp.types.vector(length=STACK, dtype=int)


# -- Warp's mesh BVH, read from kernels (layout of warp/native/bvh.h) ----------------------------


@wp.func_native("return *(((wp::Mesh*)mesh)->bvh.root);")
def bvh_root(mesh: wp.uint64) -> int: ...


@wp.func_native(
    """wp::BVHPackedNodeHalf h = ((wp::Mesh*)mesh)->bvh.node_lowers[node];
    return wp::vec3(h.x, h.y, h.z);"""
)
def bvh_lower(mesh: wp.uint64, node: int) -> wp.vec3: ...


@wp.func_native(
    """wp::BVHPackedNodeHalf h = ((wp::Mesh*)mesh)->bvh.node_uppers[node];
    return wp::vec3(h.x, h.y, h.z);"""
)
def bvh_upper(mesh: wp.uint64, node: int) -> wp.vec3: ...


@wp.func_native(
    """wp::BVHPackedNodeHalf h = ((wp::Mesh*)mesh)->bvh.node_lowers[node];
    return h.b ? -1 - (int)h.i : (int)h.i;"""
)
def bvh_left(mesh: wp.uint64, node: int) -> int:
    """The left child of an inner node, or ``-1 - first`` for a leaf of primitives ``first..``."""
    ...


@wp.func_native(
    """wp::BVHPackedNodeHalf h = ((wp::Mesh*)mesh)->bvh.node_uppers[node];
    return (int)h.i;"""
)
def bvh_right(mesh: wp.uint64, node: int) -> int:
    """The right child of an inner node, or one past the last primitive of a leaf."""
    ...


@wp.func_native("return ((wp::Mesh*)mesh)->bvh.primitive_indices[slot];")
def bvh_primitive(mesh: wp.uint64, slot: int) -> int: ...


@wp.func_native("return ((wp::Mesh*)mesh)->bvh.num_nodes;")
def bvh_node_count(mesh: wp.uint64) -> int: ...


@wp.func_native("return ((wp::Mesh*)mesh)->bvh.num_items;")
def bvh_item_count(mesh: wp.uint64) -> int: ...


# -- the same BVH repacked for packets: both children's boxes in one record, depth-first order ----


@wp.struct
class NodePair:
    """An inner node of the BVH as its two children: boxes, and each child as (record, -1) when
    inner or (first slot, end slot) of its triangles when a leaf. 64 bytes: one cache line."""

    lo_l: wp.vec3
    hi_l: wp.vec3
    lo_r: wp.vec3
    hi_r: wp.vec3
    kids: wp.vec4i  # left (a, b), right (a, b)


@wp.func
def child_code(mesh: wp.uint64, node: int, record: wp.array[wp.int32]) -> wp.vec2i:
    left = bvh_left(mesh, node)
    if left < 0:
        return wp.vec2i(-1 - left, bvh_right(mesh, node))
    return wp.vec2i(record[node], -1)


@wp.kernel
def number_inner_nodes(
    mesh: wp.uint64,
    # outputs
    record: wp.array[wp.int32],
    count: wp.array[wp.int32],
):
    """One thread: the inner nodes reachable from the root, numbered depth first (left first)."""
    stack = stack_i()
    sp = int(0)
    node = bvh_root(mesh)
    n = int(0)
    if bvh_left(mesh, node) >= 0:
        while True:
            record[node] = n
            n += 1
            left = bvh_left(mesh, node)
            right = bvh_right(mesh, node)
            inner_l = bvh_left(mesh, left) >= 0
            inner_r = bvh_left(mesh, right) >= 0
            if inner_l and inner_r:
                if sp >= STACK:  # deeper than the packets' stack: the caller traces ray by ray
                    count[0] = -1
                    return
                stack[sp] = right
                sp += 1
                node = left
                continue
            if inner_l:
                node = left
                continue
            if inner_r:
                node = right
                continue
            if sp == 0:
                break
            sp -= 1
            node = stack[sp]
    count[0] = n


@wp.kernel
def pack_node_pairs(
    mesh: wp.uint64,
    record: wp.array[wp.int32],
    # outputs
    pairs: wp.array[NodePair],
):
    node = wp.tid()
    r = record[node]
    if r < 0:
        return
    left = bvh_left(mesh, node)
    right = bvh_right(mesh, node)
    q = NodePair()
    q.lo_l = bvh_lower(mesh, left)
    q.hi_l = bvh_upper(mesh, left)
    q.lo_r = bvh_lower(mesh, right)
    q.hi_r = bvh_upper(mesh, right)
    a = child_code(mesh, left, record)
    b = child_code(mesh, right, record)
    q.kids = wp.vec4i(a[0], a[1], b[0], b[1])
    pairs[r] = q


@wp.kernel
def gather_slot_triangles(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    # outputs
    corners: wp.array[wp.vec3],
    prims: wp.array[wp.int32],
):
    slot = wp.tid()
    prim = bvh_primitive(mesh, slot)
    prims[slot] = prim
    corners[3 * slot] = points[indices[3 * prim]]
    corners[3 * slot + 1] = points[indices[3 * prim + 1]]
    corners[3 * slot + 2] = points[indices[3 * prim + 2]]


@wp.struct
class PackedBVH:
    """Warp's mesh BVH repacked for packets (:func:`pack_bvh`): inner nodes as :class:`NodePair`
    records (the root's is record 0), the triangles' corners in leaf order. ``root_leaf``: the
    slot range (a, b) when the root itself is a leaf (then ``pairs`` is a dummy), else (0, -1)."""

    pairs: wp.array[NodePair]
    corners: wp.array[wp.vec3]  # [3 * slots]
    prims: wp.array[wp.int32]  # slot -> triangle
    root_leaf: wp.vec2i
    root_lo: wp.vec3
    root_hi: wp.vec3


@wp.kernel
def root_bounds(
    mesh: wp.uint64,
    # outputs
    box: wp.array[wp.vec3],
    leaf: wp.array[wp.vec2i],
):
    """One thread: the root's box, its slot range when it is a leaf, the node and item counts."""
    node = bvh_root(mesh)
    box[0] = bvh_lower(mesh, node)
    box[1] = bvh_upper(mesh, node)
    left = bvh_left(mesh, node)
    if left < 0:
        leaf[0] = wp.vec2i(-1 - left, bvh_right(mesh, node))
    else:
        leaf[0] = wp.vec2i(0, -1)
    leaf[1] = wp.vec2i(bvh_node_count(mesh), bvh_item_count(mesh))


def pack_bvh(mesh: wp.Mesh, points: wp.array, indices: wp.array, device: str) -> tuple[PackedBVH | None, dict]:
    """Repack ``mesh``'s BVH (:class:`PackedBVH`); also returns its sizes and build time. None
    (and the reason) when the BVH is deeper than :data:`STACK`."""
    import time

    import numpy as np

    wp.synchronize_device(device)
    t0 = time.perf_counter()
    rb = wp.empty(2, dtype=wp.vec3, device=device)
    info = wp.empty(2, dtype=wp.vec2i, device=device)
    wp.launch(root_bounds, 1, inputs=[mesh.id], outputs=[rb, info], device=device)
    rbn, infon = rb.numpy(), info.numpy()
    nodes, slots = int(infon[1][0]), int(indices.shape[0] // 3)
    record = wp.full(max(nodes, 1), -1, dtype=wp.int32, device=device)
    count = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(number_inner_nodes, 1, inputs=[mesh.id], outputs=[record, count], device=device)
    n_inner = int(count.numpy()[0])
    if n_inner < 0:
        return None, {"error": f"the BVH is deeper than {STACK} levels: packets cannot walk it"}
    pairs = wp.empty(max(n_inner, 1), dtype=NodePair, device=device)
    wp.launch(pack_node_pairs, nodes, inputs=[mesh.id, record], outputs=[pairs], device=device)
    corners = wp.empty(3 * slots, dtype=wp.vec3, device=device)
    prims = wp.empty(slots, dtype=wp.int32, device=device)
    wp.launch(gather_slot_triangles, slots, inputs=[mesh.id, points, indices], outputs=[corners, prims], device=device)
    pb = PackedBVH()
    pb.pairs = pairs
    pb.corners = corners
    pb.prims = prims
    pb.root_leaf = wp.vec2i(int(infon[0][0]), int(infon[0][1]))
    pb.root_lo = wp.vec3(*np.asarray(rbn[0], float))
    pb.root_hi = wp.vec3(*np.asarray(rbn[1], float))
    wp.synchronize_device(device)
    stats = {"inner_nodes": n_inner, "slots": slots, "bytes": pairs.capacity + corners.capacity + prims.capacity,
             "build_ms": 1e3 * (time.perf_counter() - t0)}
    return pb, stats


def packed_bvh(ds) -> tuple[PackedBVH | None, dict]:
    """The packed BVH of a :class:`~wsoft.scene.device.DeviceScene`, built once and kept with it."""
    if ds.packed is None:
        ds.packed = pack_bvh(ds.mesh, ds.points, ds.indices, ds.device)
    return ds.packed


@wp.func
def lowest_bit(m: wp.uint32) -> int:
    """Index of the lowest set bit of a non-zero word."""
    return wp.bit_count(m ^ (m - wp.uint32(1))) - 1


# -- the packet's bounds -----------------------------------------------------------------------


@wp.struct
class Packet:
    """Interval bounds of rays from one origin: per axis the reciprocals of the smallest and
    largest direction component, and whether all are positive (0), negative (1) or both (0.5)."""

    o: wp.vec3
    ilo: wp.vec3
    ihi: wp.vec3
    sign: wp.vec3
    tmax: float


@wp.func
def axis_reciprocals(dlo: float, dhi: float) -> wp.vec3:
    if dlo > 0.0:
        return wp.vec3(1.0 / dlo, 1.0 / dhi, 0.0)
    if dhi < 0.0:
        return wp.vec3(1.0 / dlo, 1.0 / dhi, 1.0)
    # both signs (or zero): finite reciprocals of the extremes, for the origin-outside bounds
    return wp.vec3(1.0 / wp.min(dlo, -1.0e-30), 1.0 / wp.max(dhi, 1.0e-30), 0.5)


@wp.func
def packet_entry(pk: Packet, lo: wp.vec3, hi: wp.vec3) -> float:
    """A lower bound of the distance at which any of the packet's rays enters the box, or 1e30
    when none can reach it within the packet's longest ray.

    Per axis, with the direction components in [dlo, dhi] of one sign, a ray enters the slab
    at its near plane and leaves at the far one, both monotonic in the component: the extremes
    over the packet are at dlo or dhi (``ilo``, ``ihi`` their reciprocals). Where the packet
    has both signs, rays nearly parallel to the slab never leave it: no exit bound, and an
    entry bound only from outside."""
    tn = float(-1.0e30)
    tf = float(1.0e30)
    for a in range(3):
        near = lo[a]
        far = hi[a]
        if pk.sign[a] == 1.0:
            near = hi[a]
            far = lo[a]
        dn = near - pk.o[a]
        df = far - pk.o[a]
        if pk.sign[a] != 0.5:
            tn = wp.max(tn, wp.min(dn * pk.ilo[a], dn * pk.ihi[a]))
            tf = wp.min(tf, wp.max(df * pk.ilo[a], df * pk.ihi[a]))
        elif pk.o[a] < lo[a]:
            tn = wp.max(tn, (lo[a] - pk.o[a]) * pk.ihi[a])
        elif pk.o[a] > hi[a]:
            tn = wp.max(tn, (hi[a] - pk.o[a]) * pk.ilo[a])
    if tn <= tf and tf >= 0.0 and tn <= pk.tmax:
        return tn
    return 1.0e30


@wp.func
def packet_bounds(o: wp.vec3, dx: packet_f, dy: packet_f, dz: packet_f, tm: packet_f, mask: wp.uint32) -> Packet:
    dlo = wp.vec3(1.0e30)
    dhi = wp.vec3(-1.0e30)
    tmax = float(0.0)
    m = mask
    while m != wp.uint32(0):
        k = lowest_bit(m)
        m = m & (m - wp.uint32(1))
        dlo = wp.vec3(wp.min(dlo[0], dx[k]), wp.min(dlo[1], dy[k]), wp.min(dlo[2], dz[k]))
        dhi = wp.vec3(wp.max(dhi[0], dx[k]), wp.max(dhi[1], dy[k]), wp.max(dhi[2], dz[k]))
        tmax = wp.max(tmax, tm[k])
    rx = axis_reciprocals(dlo[0], dhi[0])
    ry = axis_reciprocals(dlo[1], dhi[1])
    rz = axis_reciprocals(dlo[2], dhi[2])
    pk = Packet()
    pk.o = o
    pk.ilo = wp.vec3(rx[0], ry[0], rz[0])
    pk.ihi = wp.vec3(rx[1], ry[1], rz[1])
    pk.sign = wp.vec3(rx[2], ry[2], rz[2])
    pk.tmax = tmax
    return pk


# -- traversal ---------------------------------------------------------------------------------


@wp.func
def leaf_hits(
    pb: PackedBVH,
    cut: Surfaces,
    has_cutouts: int,
    first: int,
    end: int,
    o: wp.vec3,
    dx: packet_f,
    dy: packet_f,
    dz: packet_f,
    tm: packet_f,
    live: wp.uint32,
) -> wp.uint32:
    """``live`` less the rays blocked by the triangles of slots ``first..end``."""
    for slot in range(first, end):
        a = pb.corners[3 * slot]
        b = pb.corners[3 * slot + 1]
        c = pb.corners[3 * slot + 2]
        m = live
        while m != wp.uint32(0):
            k = lowest_bit(m)
            m = m & (m - wp.uint32(1))
            h = ray_triangle(o, wp.vec3(dx[k], dy[k], dz[k]), a, b, c)
            if h[0] != 0.0 and h[1] < tm[k] and h[1] >= 0.0:
                # warp: p = a*u + b*v + c*(1-u-v)
                if has_cutouts == 0 or surface_present(cut, pb.prims[slot], h[2], h[3], 1.0 - h[2] - h[3]):
                    live = live & ~(wp.uint32(1) << wp.uint32(k))
        if live == wp.uint32(0):
            return live
    return live


@wp.func
def slab_reciprocal(da: float) -> float:
    """The reciprocal of a ray's direction component for the slab test (a zero component: 1e20)."""
    if da == 0.0:
        return 1.0 / 1.0e-20
    return 1.0 / da


@wp.func
def ray_meets_box(o: wp.vec3, inv: wp.vec3, tmax: float, lo: wp.vec3, hi: wp.vec3) -> bool:
    """:func:`ray_reaches_box` from the direction's reciprocals ``inv`` (:func:`slab_reciprocal`)."""
    tn = float(0.0)
    tf = tmax
    for a in range(3):
        t1 = (lo[a] - o[a]) * inv[a]
        t2 = (hi[a] - o[a]) * inv[a]
        tn = wp.max(tn, wp.min(t1, t2))
        tf = wp.min(tf, wp.max(t1, t2))
    return tn <= tf


@wp.func
def ray_reaches_box(o: wp.vec3, d: wp.vec3, tmax: float, lo: wp.vec3, hi: wp.vec3) -> bool:
    """Does the segment o + t*d, t in [0, tmax], meet the box ``lo..hi``? (slab test; callers
    pad the box so that rounding never drops a ray that meets a triangle inside it)."""
    return ray_meets_box(o, wp.vec3(slab_reciprocal(d[0]), slab_reciprocal(d[1]), slab_reciprocal(d[2])), tmax, lo, hi)


@wp.func
def padded_leaf_box(o: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    """A leaf's box padded by 1e-5 of the coordinates' magnitude (box and origin) per axis: (lo, hi)."""
    pad = (wp.vec3(wp.max(wp.abs(lo[0]), wp.abs(hi[0])) + wp.abs(o[0]), wp.max(wp.abs(lo[1]), wp.abs(hi[1])) + wp.abs(o[1]),
                   wp.max(wp.abs(lo[2]), wp.abs(hi[2])) + wp.abs(o[2])) + wp.vec3(1.0)) * 1.0e-5
    return lo - pad, hi + pad


@wp.func
def rays_reaching_leaf(o: wp.vec3, dx: packet_f, dy: packet_f, dz: packet_f, tm: packet_f, live: wp.uint32, lo: wp.vec3,
                       hi: wp.vec3) -> wp.uint32:
    """The rays of ``live`` whose segment meets the leaf's box, padded by 1e-5 of the coordinates'
    magnitude (box and origin) per axis: conservative, a ray that meets a triangle of the leaf is
    kept (the padded box also has thickness where the leaf's triangles lie in one axis plane)."""
    blo, bhi = padded_leaf_box(o, lo, hi)
    sub = wp.uint32(0)
    m = live
    while m != wp.uint32(0):
        k = lowest_bit(m)
        m = m & (m - wp.uint32(1))
        if ray_reaches_box(o, wp.vec3(dx[k], dy[k], dz[k]), tm[k], blo, bhi):
            sub = sub | (wp.uint32(1) << wp.uint32(k))
    return sub


@wp.func
def rays_meeting_leaf(o: wp.vec3, ix: packet_f, iy: packet_f, iz: packet_f, tm: packet_f, live: wp.uint32, lo: wp.vec3,
                      hi: wp.vec3) -> wp.uint32:
    """:func:`rays_reaching_leaf` from the rays' direction reciprocals (:func:`slab_reciprocal`,
    computed once a packet: the same answer without three divisions a ray and leaf)."""
    blo, bhi = padded_leaf_box(o, lo, hi)
    sub = wp.uint32(0)
    m = live
    while m != wp.uint32(0):
        k = lowest_bit(m)
        m = m & (m - wp.uint32(1))
        if ray_meets_box(o, wp.vec3(ix[k], iy[k], iz[k]), tm[k], blo, bhi):
            sub = sub | (wp.uint32(1) << wp.uint32(k))
    return sub


@wp.func
def visit_child(
    pb: PackedBVH,
    cut: Surfaces,
    has_cutouts: int,
    child: wp.vec2i,
    t: float,
    lo: wp.vec3,
    hi: wp.vec3,
    o: wp.vec3,
    dx: packet_f,
    dy: packet_f,
    dz: packet_f,
    tm: packet_f,
    ix: packet_f,
    iy: packet_f,
    iz: packet_f,
    live: wp.uint32,
    work: int,
):
    """One child (box ``lo..hi``) of a record whose box the packet enters at ``t`` (1e30: never):
    an inner child is returned to descend into (else -1); a leaf's triangles are tested on the
    spot, each against the rays whose own segment meets the leaf's box (:func:`rays_meeting_leaf`,
    from the directions' reciprocals ``ix``, ``iy``, ``iz``:
    the packet's bounds reach boxes that most of its rays miss). Returns (live, inner record or
    -1, work done so far: a ray-box test counts half a ray-triangle test)."""
    if t >= 1.0e30:
        return live, -1, work
    if child[1] >= 0:
        sub = live
        if wp.bit_count(live) > 1:
            sub = rays_meeting_leaf(o, ix, iy, iz, tm, live, lo, hi)
            work += wp.bit_count(live) / 2
        if sub == wp.uint32(0):
            return live, -1, work
        work += (child[1] - child[0]) * wp.bit_count(sub)
        return (live & ~sub) | leaf_hits(pb, cut, has_cutouts, child[0], child[1], o, dx, dy, dz, tm, sub), -1, work
    return live, child[0], work


@wp.func
def trace_packet(
    mesh: wp.uint64,
    pb: PackedBVH,
    cut: Surfaces,
    has_cutouts: int,
    o: wp.vec3,
    dx: packet_f,
    dy: packet_f,
    dz: packet_f,
    tm: packet_f,
    mask: wp.uint32,
):
    """Rays ``k`` of ``mask`` (origin ``o``, unit direction ``(dx[k], dy[k], dz[k])``, length
    ``tm[k]``) traced together; returns (the bits of the rays that reach their length unblocked,
    1 when the packet gave up and finished ray by ray, else 0). A ray is blocked by a triangle
    hit at ``0 <= t < tm[k]`` that is present there (cutouts), as
    :func:`~wsoft.scene.surfaces.occluded` has it. The pending nodes never exceed :data:`STACK`
    (:func:`pack_bvh` checked the tree).

    A packet is worth it while its rays share the nodes and triangles they reach. Where they fan
    out over fine geometry (light through foliage) the packet's bounds reach far more than any
    one ray: past :data:`WORK_PER_RAY` node visits and ray-triangle tests per ray, the packet
    stops and its rays still unblocked go one by one through :func:`occluded` (the same answer)."""
    live = mask
    if live == wp.uint32(0):
        return live, 0
    pk = packet_bounds(o, dx, dy, dz, tm, mask)
    if packet_entry(pk, pb.root_lo, pb.root_hi) >= 1.0e30:
        return live, 0
    if pb.root_leaf[1] >= 0:
        return leaf_hits(pb, cut, has_cutouts, pb.root_leaf[0], pb.root_leaf[1], o, dx, dy, dz, tm, live), 0
    budget = WORK_PER_RAY * wp.bit_count(mask)
    work = int(0)
    ix = packet_f()
    iy = packet_f()
    iz = packet_f()
    for k in range(PACKET):  # every lane (an unused one's reciprocal is never read): a loop the compiler can vectorise
        ix[k] = slab_reciprocal(dx[k])
        iy[k] = slab_reciprocal(dy[k])
        iz[k] = slab_reciprocal(dz[k])
    stack = stack_i()
    sp = int(0)
    rec = int(0)
    while True:
        if work > budget:
            break
        q = pb.pairs[rec]
        work += 1
        # the nearer child first (the left one on a tie)
        near = wp.vec2i(q.kids[0], q.kids[1])
        far = wp.vec2i(q.kids[2], q.kids[3])
        t_near = packet_entry(pk, q.lo_l, q.hi_l)
        t_far = packet_entry(pk, q.lo_r, q.hi_r)
        lo_n = q.lo_l
        hi_n = q.hi_l
        lo_f = q.lo_r
        hi_f = q.hi_r
        if t_far < t_near:
            near, far = far, near
            t_near, t_far = t_far, t_near
            lo_n = q.lo_r
            hi_n = q.hi_r
            lo_f = q.lo_l
            hi_f = q.hi_l
        live, n0, work = visit_child(pb, cut, has_cutouts, near, t_near, lo_n, hi_n, o, dx, dy, dz, tm, ix, iy, iz, live, work)
        live, n1, work = visit_child(pb, cut, has_cutouts, far, t_far, lo_f, hi_f, o, dx, dy, dz, tm, ix, iy, iz, live, work)
        if live == wp.uint32(0):
            return live, 0
        if n0 >= 0 and n1 >= 0:
            stack[sp] = n1
            sp += 1
            rec = n0
            continue
        if n0 >= 0:
            rec = n0
            continue
        if n1 >= 0:
            rec = n1
            continue
        if sp == 0:
            return live, 0
        sp -= 1
        rec = stack[sp]
    return trace_each(mesh, cut, has_cutouts, o, dx, dy, dz, tm, live), 1


@wp.func
def trace_each(
    mesh: wp.uint64,
    cut: Surfaces,
    has_cutouts: int,
    o: wp.vec3,
    dx: packet_f,
    dy: packet_f,
    dz: packet_f,
    tm: packet_f,
    live: wp.uint32,
) -> wp.uint32:
    """The rays of ``live`` one by one through Warp's per-ray any-hit (:func:`occluded`): the
    bits of those that reach their length unblocked."""
    m = live
    while m != wp.uint32(0):
        k = lowest_bit(m)
        m = m & (m - wp.uint32(1))
        if occluded(mesh, cut, has_cutouts, o, wp.vec3(dx[k], dy[k], dz[k]), tm[k]):
            live = live & ~(wp.uint32(1) << wp.uint32(k))
    return live


@wp.func
def trace_receiver_packet(
    mesh: wp.uint64,
    pb: PackedBVH,
    cut: Surfaces,
    has_cutouts: int,
    o: wp.vec3,
    dx: packet_f,
    dy: packet_f,
    dz: packet_f,
    tm: packet_f,
    mask: wp.uint32,
    each: int,
):
    """One packet of a receiver's rays: through :func:`trace_packet` until one of the receiver's
    packets has given up (``each`` = 1), then ray by ray (:func:`trace_each`). Returns (the bits
    of the rays unblocked, ``each`` for the receiver's next packet)."""
    if each != 0:
        return trace_each(mesh, cut, has_cutouts, o, dx, dy, dz, tm, mask), 1
    return trace_packet(mesh, pb, cut, has_cutouts, o, dx, dy, dz, tm, mask)
