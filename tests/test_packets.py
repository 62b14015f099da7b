"""Packet traversal of shadow rays (``wsoft.reference.packets``) against Warp's per-ray any-hit, bit for
bit, on every light kind, with cutouts, and for sample counts that leave a packet partly filled;
the known differences (where the packet agrees with the brute force and Warp's per-ray walk
does not); the leaf filter's conservativeness; packets that give up on fine geometry."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import scene_path

import wsoft
from wsoft.reference.packets import PACKET, pack_bvh, packet_f, rays_reaching_leaf
from wsoft.scene.rays import ray_triangle
from wsoft.scene.surfaces import Surfaces, surface_present
from wsoft.stages import add_box, add_camera, add_point_light, add_quad, make_stage

CASES = [
    ("contact.usda", None),  # rect light, contact shadows
    ("multi_light.usda", "Rect"),
    ("multi_light.usda", "Disk"),
    ("multi_light.usda", "Sphere"),
    ("multi_light.usda", "Sun"),
    ("cutout.usda", None),  # alpha-tested cutouts
]


@pytest.mark.parametrize("scene,light", CASES)
@pytest.mark.parametrize("samples", [16, 37])
def test_packets_equal_per_ray_bit_for_bit(device, scene, light, samples):
    s = wsoft.load_scene(scene_path(scene))
    kw = {"width": 48, "height": 36, "device": device, "samples": samples, "light": light}
    ray = wsoft.render(s, "reference", traversal="ray", **kw)
    packet = wsoft.render(s, "reference", traversal="packet", **kw)
    assert packet.counters()["traversal"] == "packet" and ray.counters()["traversal"] == "ray"
    assert np.array_equal(ray.V, packet.V)
    assert np.array_equal(ray["V_stderr"], packet["V_stderr"])
    cov = ray["A"] > 0
    assert ((ray.V < 1) & cov).sum() > 20 and ((ray.V > 0) & (ray.V < 1) & cov).any()  # shadow and penumbra: the interesting case
    if samples > PACKET:
        assert samples % PACKET  # a partly filled last packet


def test_packets_on_a_point_light_and_a_bvh_that_is_one_leaf(device):
    """A point light (every sample the same ray) and a stage small enough for the BVH's root to be a leaf."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 2.0)
    add_box(st, "/World/Box", (-0.3, -0.3, 0.2), (0.3, 0.3, 0.6))
    add_point_light(st, "/World/Point", (0.4, 0.2, 3.0))
    add_camera(st, "/World/Cam", (0, -4, 3), (0, 0, 0))
    s = wsoft.load_scene(st)
    kw = {"width": 40, "height": 30, "device": device, "samples": 16}
    ray = wsoft.render(s, "reference", traversal="ray", **kw)
    packet = wsoft.render(s, "reference", traversal="packet", **kw)
    assert np.array_equal(ray.V, packet.V)
    assert set(np.unique(ray.V[ray["A"] > 0])) == {0.0, 1.0}  # a point light: hard shadows, and some of each
    ds, _ = s.device_copy(device, __import__("wsoft.scene.device", fromlist=["upload_scene"]).upload_scene)
    pb, info = pack_bvh(ds.mesh, ds.points, ds.indices, device)
    assert pb is not None and info["slots"] == s.triangle_count


def test_explicit_ray_packets_equal_per_ray(device):
    """The throughput benchmark's explicit rays (consecutive per receiver, one origin) in packets."""
    from wsoft.lightspace.light import disk_shaped
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.reference import reference_pattern, shadow_rays, trace_ray_packets, trace_rays
    from wsoft.pipeline import RenderContext, frame_setup
    from wsoft.scene.device import upload_scene

    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    light = scene.find_light("Disk")
    ds, _ = scene.device_copy(device, upload_scene)
    ctx = RenderContext(scene, frame_setup(scene, 40, 30).camera, 40, 30, device)
    gb = render_gbuffer(ds, camera_gpu(ctx.camera), 40, 30, 1, scene.has_cutouts)
    pattern = reference_pattern(40, 3, True)
    o, d, t = shadow_rays(ds, ctx.light_gpu(light), gb, pattern, disk_shaped(light))
    a = trace_rays(ds, o, d, t).numpy()
    b = trace_ray_packets(ds, o, d, t, pattern.count).numpy()
    assert np.array_equal(a, b)
    assert 0 < a.mean() < 1


def test_traversal_is_chosen_by_device_and_samples():
    from wsoft.reference import PACKET_MIN_SAMPLES, resolve_traversal

    assert resolve_traversal("auto", "cpu", 64) == "packet"
    assert resolve_traversal("auto", "cpu", PACKET_MIN_SAMPLES - 1) == "ray"
    assert resolve_traversal("auto", "cuda:0", 64) == "ray"
    assert resolve_traversal("packet", "cuda:0", 1) == "packet"
    with pytest.raises(ValueError, match="traversal"):
        resolve_traversal("frustum", "cpu", 16)
    with pytest.raises(wsoft.ParameterError, match="traversal"):
        wsoft.render(wsoft.load_scene(scene_path("box_plane.usda")), "reference", width=8, height=6, traversal="frustum")


def test_a_bvh_too_deep_for_packets_falls_back_to_rays_and_says_so(monkeypatch):
    """pack_bvh refuses a tree whose walk would overflow the packets' stack; the reference then
    traces ray by ray, with the reason in its counters and a warning."""
    import wsoft.reference.packets as packets

    monkeypatch.setattr(packets, "pack_bvh", lambda *a, **k: (None, {"error": "the BVH is deeper than 64 levels: packets cannot walk it"}))
    s = wsoft.load_scene(scene_path("contact.usda"))
    fr = wsoft.render(s, "reference", width=32, height=24, samples=16, traversal="packet")
    c = fr.counters()
    assert c["traversal"] == "ray" and "deeper than 64" in c["packet_fallback"]
    assert any("ray by ray" in w for w in fr.stats["warnings"])
    ref = wsoft.render(s, "reference", width=32, height=24, samples=16, traversal="ray")
    assert np.array_equal(fr.V, ref.V)


def test_packed_bvh_keeps_warps_tree():
    """Every triangle once in the leaves, corners as the mesh has them; the records' boxes hold
    their children's triangles."""
    scene = wsoft.load_scene(scene_path("contact.usda"))
    from wsoft.scene.device import upload_scene

    ds, _ = scene.device_copy("cpu", upload_scene)
    pb, info = pack_bvh(ds.mesh, ds.points, ds.indices, "cpu")
    prims = pb.prims.numpy()
    assert sorted(prims.tolist()) == list(range(scene.triangle_count))
    corners = pb.corners.numpy().reshape(-1, 3, 3)
    pts, idx = ds.points.numpy(), ds.indices.numpy().reshape(-1, 3)
    assert np.array_equal(corners, pts[idx[prims]])
    pairs = pb.pairs.numpy()
    assert info["inner_nodes"] == len(pairs) > 10
    for rec in pairs:
        for side, (a, b) in ((0, rec["kids"][:2]), (1, rec["kids"][2:])):
            lo, hi = (rec["lo_l"], rec["hi_l"]) if side == 0 else (rec["lo_r"], rec["hi_r"])
            if b >= 0:  # a leaf: its triangles inside its box
                c = corners[a:b].reshape(-1, 3)
                assert np.all(c >= lo - 1e-6) and np.all(c <= hi + 1e-6)
            else:  # an inner child: a later record (depth first)
                assert 0 < a < len(pairs)
    wp.synchronize()


@wp.kernel
def brute_force_hits(orig: wp.vec3, dirn: wp.vec3, tmax: float, pts: wp.array[wp.vec3], ind: wp.array[wp.int32], cut: Surfaces,
                     at: wp.array[float], present: wp.array[wp.int32]):
    """Every triangle against one ray with Warp's own test: where it hits (``at``, -1 if not) and
    whether the surface is there (the alpha test of a cutout; 1 on an opaque triangle)."""
    i = wp.tid()
    h = ray_triangle(orig, dirn, pts[ind[3 * i]], pts[ind[3 * i + 1]], pts[ind[3 * i + 2]])
    at[i] = -1.0
    present[i] = 0
    if h[0] != 0.0 and h[1] < tmax and h[1] >= 0.0:
        at[i] = h[1]
        present[i] = wp.where(surface_present(cut, i, h[2], h[3], 1.0 - h[2] - h[3]), 1, 0)


def _pixel_rays(file: str, light_path: str, x: int, y: int):
    """The 64 reference rays (seed 1) of pixel (x, y) of a 640 x 480 view, traced per ray and in a
    packet, and a brute force over every triangle for any one of them."""
    from wsoft.lightspace.light import disk_shaped
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.reference import generate_shadow_rays, reference_pattern, trace_ray_packets, trace_rays
    from wsoft.pipeline import RenderContext, frame_setup
    from wsoft.scene.device import upload_scene

    scene = wsoft.load_scene(scene_path(file))
    light = scene.find_light(light_path)
    ds, _ = scene.device_copy("cpu", upload_scene)
    ctx = RenderContext(scene, frame_setup(scene, 640, 480).camera, 640, 480, "cpu")
    gb = render_gbuffer(ds, camera_gpu(ctx.camera), 640, 480, 1, scene.has_cutouts)
    pattern = reference_pattern(64, 1, True)
    pix = wp.array([y * 640 + x], dtype=wp.int32)
    o, d, t = (wp.empty(64, dtype=wp.vec3), wp.empty(64, dtype=wp.vec3), wp.empty(64, dtype=float))
    wp.launch(generate_shadow_rays, 1, inputs=[0, ctx.light_gpu(light), pattern.on("cpu", disk_shaped(light)), gb.gpu(), pix],
                                         outputs=[o, d, t])
    per_ray, packet = trace_rays(ds, o, d, t).numpy(), trace_ray_packets(ds, o, d, t, 64).numpy()

    def brute(r: int):
        at, present = wp.empty(scene.triangle_count, dtype=float), wp.empty(scene.triangle_count, dtype=wp.int32)
        wp.launch(brute_force_hits, scene.triangle_count, inputs=[wp.vec3(o.numpy()[r]), wp.vec3(d.numpy()[r]), float(t.numpy()[r]),
                                                                  ds.points, ds.indices, ds.cutouts], outputs=[at, present])
        return at.numpy(), present.numpy()

    return scene, per_ray, packet, brute


def test_a_ray_grazing_a_shared_edge_that_warps_per_ray_walk_drops():
    """One of the differences found in ``wsoft bench foundation`` (city, Rect light, 640 x 480,
    64 samples, seed 1: one ray of 19.7 million): a shadow ray through the shared edge of two
    axis-aligned triangles (each with a zero-thickness box). Warp's own triangle test hits both
    at t = 50.8; its per-ray walk drops their box and reports the ray unblocked, the packet's
    conservative bounds reach it. The packet agrees with the brute force over every triangle."""
    scene, per_ray, packet, brute = _pixel_rays("city.usdc", "/World/Lights/Rect", 79, 247)
    assert not scene.has_cutouts  # every triangle hit is present
    differ = np.nonzero(per_ray != packet)[0]
    assert len(differ) <= 1
    for r in list(differ) + [0, 1, 2]:  # the differing ray, and a few others as a control
        at, _ = brute(r)
        assert packet[r] == int((at >= 0).any())


def _kept_rays(file: str, origin: list[str], dirs: list[list[str]], tmax: list[str]):
    """Rays kept as numbers (float32 written with ``float.hex``: one origin, a direction and a
    length each), traced per ray and in a packet, and a brute force over every triangle for any one
    of them. They are rays of the reference at 640 x 480, 64 samples, seed 1, as its chained random
    draws placed them: a case found once stays the same case whatever the samples become."""
    from wsoft.reference import trace_ray_packets, trace_rays
    from wsoft.scene.device import upload_scene

    scene = wsoft.load_scene(scene_path(file))
    ds, _ = scene.device_copy("cpu", upload_scene)
    n = len(dirs)
    o = wp.array(np.array([[float.fromhex(v) for v in origin]] * n, np.float32), dtype=wp.vec3)
    d = wp.array(np.array([[float.fromhex(v) for v in dv] for dv in dirs], np.float32), dtype=wp.vec3)
    t = wp.array(np.array([float.fromhex(v) for v in tmax], np.float32), dtype=float)
    per_ray, packet = trace_rays(ds, o, d, t).numpy(), trace_ray_packets(ds, o, d, t, n).numpy()

    def brute(r: int):
        at, present = wp.empty(scene.triangle_count, dtype=float), wp.empty(scene.triangle_count, dtype=wp.int32)
        wp.launch(brute_force_hits, scene.triangle_count, inputs=[wp.vec3(o.numpy()[r]), wp.vec3(d.numpy()[r]), float(t.numpy()[r]),
                                                                  ds.points, ds.indices, ds.cutouts], outputs=[at, present])
        return at.numpy(), present.numpy()

    return scene, per_ray, packet, brute


def test_a_ray_through_a_cutout_cards_shared_edge_meets_the_card_behind_its_hole():
    """A shadow ray through the shared edge of two triangles of one alpha-tested card (hl2_like, Sky
    light, pixel (411, 313), its rays 0-3, ray 2 the case), a hole in the first and present in the
    second. The per-ray walk steps a few ulps past the hole
    (:func:`~wsoft.scene.offsets.step_past`), so it meets the second: blocked, as the packet (which
    tests every triangle it reaches at its own hit) and the brute force over every triangle with the
    alpha test have it."""
    scene, per_ray, packet, brute = _kept_rays(
        "hl2_like.usdc", ["-0x1.2ef4b0p+2", "-0x1.884288p+3", "0x1.933334p-16"],
        [["-0x1.348ce6p-1", "0x1.1198aep-1", "0x1.2f74cep-1"], ["-0x1.391546p-1", "0x1.0f8838p-1", "0x1.2ca79ep-1"],
         ["-0x1.3ab22cp-1", "0x1.0e0db6p-1", "0x1.2c4d6cp-1"], ["-0x1.3d28eap-1", "0x1.0acfb0p-1", "0x1.2c9bbep-1"]],
        ["0x1.55c298p+8"] * 4)
    assert np.array_equal(per_ray, packet)
    at, present = brute(2)
    hit = np.nonzero(at >= 0)[0]
    first, behind = hit[np.argsort(at[hit])][:2]
    assert present[first] == 0 and present[behind] == 1  # a hole, then the card itself
    assert 0 < at[behind] - at[first]
    assert scene.tri_prim[first] == scene.tri_prim[behind]  # one card
    assert per_ray[2] == 1
    for r in (0, 1, 3):  # a few others as a control
        assert packet[r] == int(brute(r)[1].any())


def test_a_ray_past_a_hole_meets_the_next_cutout_where_its_own_origin_does():
    """A shadow ray past a hole that meets the next cutout on the edge of its hole (greece, Light1,
    pixel (391, 197), its rays 0, 1, 2 and 7, ray 7 the case): the per-ray walk re-queries from a
    few ulps past the hole and meets the cutout at the point the ray from its own origin does, in
    its hole, as the packet and the brute force over every triangle with the alpha test have it."""
    scene, per_ray, packet, brute = _kept_rays(
        "greece.usdc", ["0x1.33c4a6p+2", "-0x1.9999eap+1", "0x1.28ce5cp+2"],
        [["-0x1.fc28dep-1", "-0x1.74d3d6p-4", "0x1.4e459ep-4"], ["-0x1.fb269ep-1", "-0x1.95b3a4p-4", "0x1.857a9ep-4"],
         ["-0x1.fb0b1ap-1", "-0x1.8fb494p-4", "0x1.945a02p-4"], ["-0x1.f83c8ap-1", "-0x1.80ab28p-4", "0x1.2abb46p-3"]],
        ["0x1.7ce476p+3", "0x1.7cd80ap+3", "0x1.7ccd6cp+3", "0x1.7ce99ep+3"])
    assert np.array_equal(per_ray, packet)
    at, present = brute(3)
    hit = np.nonzero(at >= 0)[0]
    assert len(hit) >= 2  # two triangles on its way: the hole and the next cutout
    assert per_ray[3] == packet[3] == int(present[hit].any()) == 0
    for r in (0, 1, 2):  # a few others as a control
        assert packet[r] == int(brute(r)[1].any())


def test_packets_give_up_on_fine_geometry_and_stay_exact(device):
    """Light through foliage: a receiver's rays fan out over leaves smaller than their spread, so
    the packet's bounds reach far more than any one ray; it gives up and goes ray by ray, with the
    same answer."""
    s = wsoft.load_scene(scene_path("fig1_plant.usdc"))
    kw = {"width": 64, "height": 48, "device": device, "samples": 32}
    ray = wsoft.render(s, "reference", traversal="ray", **kw)
    packet = wsoft.render(s, "reference", traversal="packet", **kw)
    assert np.array_equal(ray.V, packet.V)
    c = packet.counters()
    covered = int((packet["A"] > 0).sum())
    assert 0.05 * covered < c["receivers_ray_by_ray"] < covered  # some gave up, not all


@wp.kernel
def leaf_filter_keeps_hits(tri: wp.array[wp.vec3], orig: wp.array[wp.vec3], target: wp.array[wp.vec3],
                           # outputs
                           hit: wp.array[wp.int32], kept: wp.array[wp.int32]):
    """Case i: one ray from ``orig[i]`` through ``target[i]`` (a little past it) against triangle i:
    does Warp's test hit it, and does the packets' leaf filter keep the ray for the triangle's box?"""
    i = wp.tid()
    a = tri[3 * i]
    b = tri[3 * i + 1]
    c = tri[3 * i + 2]
    o = orig[i]
    d = wp.normalize(target[i] - o)
    tmax = wp.length(target[i] - o) * 1.01
    h = ray_triangle(o, d, a, b, c)
    hit[i] = wp.where(h[0] != 0.0 and h[1] >= 0.0 and h[1] < tmax, 1, 0)
    dx = packet_f()
    dy = packet_f()
    dz = packet_f()
    tm = packet_f()
    dx[3] = d[0]
    dy[3] = d[1]
    dz[3] = d[2]
    tm[3] = tmax
    lo = wp.vec3(wp.min(wp.min(a[0], b[0]), c[0]), wp.min(wp.min(a[1], b[1]), c[1]), wp.min(wp.min(a[2], b[2]), c[2]))
    hi = wp.vec3(wp.max(wp.max(a[0], b[0]), c[0]), wp.max(wp.max(a[1], b[1]), c[1]), wp.max(wp.max(a[2], b[2]), c[2]))
    kept[i] = wp.where(rays_reaching_leaf(o, dx, dy, dz, tm, wp.uint32(8), lo, hi) == wp.uint32(8), 1, 0)


@pytest.mark.parametrize("offset", [0.0, 1.0e3, 3.0e4])
def test_the_leaf_filter_never_drops_a_ray_that_hits_the_leafs_triangle(offset):
    """A packet tests a leaf's triangles only against the rays whose own segment meets the leaf's
    box (:func:`rays_reaching_leaf`). That filter must be conservative: every ray Warp's triangle
    test hits is kept, for triangles in an axis plane (a box of zero thickness), rays aimed at their
    corners and edges (where a slab test rounds either way), grazing rays, and coordinates far from
    the origin."""
    rng = np.random.default_rng(7)
    n = 20000
    base = rng.uniform(-1.0, 1.0, (n, 1, 3)) * 5.0 + offset
    tri = base + rng.uniform(-1.0, 1.0, (n, 3, 3)) * rng.choice([1e-3, 0.1, 2.0], (n, 1, 1))
    flat = rng.integers(0, 4, n)  # 0..2: the triangle lies in a plane of that axis; 3: general
    for ax in range(3):
        tri[flat == ax, :, ax] = tri[flat == ax, :1, ax]
    w = rng.dirichlet([1.0, 1.0, 1.0], n)
    corner = rng.integers(0, 3, n)
    kind = rng.integers(0, 3, n)  # 0 inside, 1 on an edge, 2 at a corner
    w[kind == 1, corner[kind == 1]] = 0.0
    w[kind == 2] = np.eye(3)[corner[kind == 2]]
    w /= w.sum(1, keepdims=True)
    target = np.einsum("nk,nkj->nj", w, tri)
    direction = rng.normal(size=(n, 3))
    direction[rng.random(n) < 0.3] *= np.array([1.0, 1.0, 1e-4])  # grazing a z-plane
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    orig = target - direction * rng.uniform(0.01, 50.0, (n, 1))
    away = rng.random(n) < 0.2  # the same ray moved off the triangle: most of these miss its box
    shift = rng.normal(size=(n, 3))
    shift *= (3.0 * (np.ptp(tri, axis=1).max(1) + 1.0) / np.linalg.norm(shift, axis=1))[:, None]
    orig[away] += shift[away]
    target[away] += shift[away]
    tri32, o32, t32 = (np.ascontiguousarray(x, np.float32) for x in (tri.reshape(-1, 3), orig, target))
    hit, kept = wp.empty(n, dtype=wp.int32), wp.empty(n, dtype=wp.int32)
    wp.launch(leaf_filter_keeps_hits, n, inputs=[wp.array(tri32, dtype=wp.vec3), wp.array(o32, dtype=wp.vec3), wp.array(t32, dtype=wp.vec3)],
              outputs=[hit, kept], device="cpu")
    hit, kept = hit.numpy(), kept.numpy()
    assert hit[~away].sum() > 0.3 * (~away).sum()  # many rays aimed at the triangle hit it (not all: corners, edges, float32 slivers far out)
    assert np.all(kept[hit == 1] == 1)
    assert (kept[away] == 0).mean() > 0.5  # and the filter drops rays that miss the box


def test_this_warps_bvh_layout_is_the_one_the_packets_read(device):
    """The start-up check (a known mesh walked with the node readers, against mesh_query_ray)
    passes on the Warp installed."""
    from wsoft.reference.layout import layout_mismatch

    assert layout_mismatch(device) is None


def test_an_unreadable_bvh_layout_traces_ray_by_ray_with_one_warning(monkeypatch):
    """A Warp whose BVH layout the packets do not read (the check forced to fail): one warning for
    the process, and the reference traces ray by ray, with the same V."""
    import wsoft.reference.layout as layout

    monkeypatch.setattr(layout, "layout_mismatch", lambda device: "forced by the test")
    monkeypatch.setattr(layout, "_layout_checked", {})
    s = wsoft.load_scene(scene_path("contact.usda"))
    with pytest.warns(RuntimeWarning, match="BVH layout is not the one wsoft.reference.packets reads") as caught:
        auto = wsoft.render(s, "reference", width=32, height=24, samples=16)
        packet = wsoft.render(s, "reference", width=32, height=24, samples=16, traversal="packet")
    assert sum("BVH layout" in str(w.message) for w in caught) == 1
    assert auto.counters()["traversal"] == packet.counters()["traversal"] == "ray"
    ray = wsoft.render(s, "reference", width=32, height=24, samples=16, traversal="ray")
    assert np.array_equal(auto.V, ray.V) and np.array_equal(packet.V, ray.V)
    assert 0.0 < float(ray.V.mean()) < 1.0
