"""Backprojection soft shadow mapping (``ssm``): pruning structures and microrects against brute
force, the exact parallel-rectangle case, bitmask against area, smooth LOQ, the MSAA resolve, bad
input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from conftest import box_plane_ground_error, scene_path

import wsoft
from wsoft.accel.ssm_structures import build_microrects, build_structure, query
from wsoft.raster.gbuffer import GBuffer
from wsoft.techniques.ssm import msaa_resolve

INF = float("inf")


def _random_map(n: int, seed: int) -> np.ndarray:
    """Blocks of random depth (casters), noise, and empty texels."""
    rng = np.random.default_rng(seed)
    d = np.kron(rng.random((n // 4, n // 4)), np.ones((4, 4))) + 0.05 * rng.random((n, n))
    d[rng.random((n, n)) < 0.08] = 1e30
    return d.astype(np.float32)


def _random_rects(n: int, count: int, seed: int, max_side: int, aspect: float | None = None) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        x0, y0 = rng.integers(0, n, 2)
        w, h = rng.integers(1, max_side + 1, 2)
        x1, y1 = min(x0 + w - 1, n - 1), min(y0 + h - 1, n - 1)
        lx, ly = x1 - x0 + 1, y1 - y0 + 1
        if aspect is None or max(lx, ly) <= aspect * min(lx, ly):
            out.append((x0, y0, x1, y1))
    return np.asarray(out, np.int32)


@pytest.mark.parametrize("kind", ["hsm", "mssm", "ysm"])
def test_depth_ranges_against_brute_force(device, kind):
    n = 64
    d = _random_map(n, 1)
    s = build_structure(kind, wp.array(d, dtype=float, device=device), device, ysm_size=16)
    rects = _random_rects(n, 600, 2, 40)
    got = query(s, rects, device)
    exact = np.array([[d[y0:y1 + 1, x0:x1 + 1].min(), d[y0:y1 + 1, x0:x1 + 1].max()] for x0, y0, x1, y1 in rects])
    assert np.all(got[:, 0] <= exact[:, 0]) and np.all(got[:, 1] >= exact[:, 1])  # always conservative
    if kind == "mssm":  # exact while the squares tile the rectangle (aspect <= 2)
        sq = _random_rects(n, 400, 3, 40, aspect=2.0)
        g2 = query(s, sq, device)
        e2 = np.array([[d[y0:y1 + 1, x0:x1 + 1].min(), d[y0:y1 + 1, x0:x1 + 1].max()] for x0, y0, x1, y1 in sq])
        assert np.array_equal(g2, e2)
    # every structure is exact on blocks aligned to its grid (HSM: 2^k blocks; YSM: its 4-texel grid)
    blocks = np.array([(x, y, x + 7, y + 7) for x in range(0, n, 8) for y in range(0, n, 8)], np.int32)
    gb = query(s, blocks, device)
    eb = np.array([[d[y0:y1 + 1, x0:x1 + 1].min(), d[y0:y1 + 1, x0:x1 + 1].max()] for x0, y0, x1, y1 in blocks])
    assert np.array_equal(gb, eb)
    # the HSM is looser than the MSSM on unaligned rectangles (the interesting case happens)
    if kind == "hsm":
        assert np.mean(got[:, 0] < exact[:, 0]) > 0.1


def test_structure_memory_matches_the_papers_layout():
    """Table 1's footprints follow from the layout: HSM 4/3 N^2, MSSM (log2 N + 1) N^2, YSM HSM + log2(256) 256^2, vec2 of float32."""
    d = wp.zeros((1024, 1024), dtype=float, device="cpu")
    mb = {k: build_structure(k, d, "cpu").memory_bytes() / 2**20 for k in ("hsm", "mssm", "ysm")}
    assert abs(mb["hsm"] - 10.67) < 0.01 and abs(mb["mssm"] - 88.0) < 0.01 and abs(mb["ysm"] - 14.67) < 0.01


def _microrects_reference(d: np.ndarray, levels: int, diagonal: str = "paper", tie: float = 1e-6):
    """Pure-Python greedy two-pass merge, tracking each microrect's level-0 member texels. A
    diagonal the first pass leaves goes to the retained one at +x+y (``paper``) or to the
    retained neighbour of nearest depth, ties in the order +x+y, +x-y, -x+y, -x-y (``nearest``).
    Depth differences within ``tie`` (relative) are equal, the tie going to the first partner."""
    n = d.shape[0]
    members = {(a, b): [(a, b)] for a in range(n) for b in range(n)}
    dep = {(a, b): float(d[b, a]) for a in range(n) for b in range(n)}

    def bbox(ms):
        xs, ys = [m[0] for m in ms], [m[1] for m in ms]
        return (min(xs), min(ys), max(xs), max(ys))

    out = []
    for _ in range(levels):
        m = n
        ext = {k: bbox(v) for k, v in members.items()}
        take = {}  # level-i texel -> owner (a, b) at level i (even, even)

        def closer(x, first, second, dep=dep):
            return abs(dep[x] - dep[first]) <= abs(dep[x] - dep[second]) + tie * abs(dep[x])

        for a in range(0, m, 2):
            for b in range(0, m, 2):
                take[(a, b)] = (a, b)
                e = ext[(a, b)]
                if a + 1 < m and (a + 2 >= m or closer((a + 1, b), (a, b), (a + 2, b))):
                    take[(a + 1, b)] = (a, b)
                    e = (min(e[0], ext[(a + 1, b)][0]), min(e[1], ext[(a + 1, b)][1]), max(e[2], ext[(a + 1, b)][2]), max(e[3], ext[(a + 1, b)][3]))
                if b + 1 < m and (b + 2 >= m or closer((a, b + 1), (a, b), (a, b + 2))):
                    take[(a, b + 1)] = (a, b)
                    e = (min(e[0], ext[(a, b + 1)][0]), min(e[1], ext[(a, b + 1)][1]), max(e[2], ext[(a, b + 1)][2]), max(e[3], ext[(a, b + 1)][3]))
                if a + 1 < m and b + 1 < m:
                    de = ext[(a + 1, b + 1)]
                    if a + 2 >= m or b + 2 >= m or (e[0] <= de[0] and e[1] <= de[1] and e[2] >= de[2] and e[3] >= de[3]):
                        take[(a + 1, b + 1)] = (a, b)
        if diagonal == "nearest":
            for dx in range(1, m, 2):
                for dy in range(1, m, 2):
                    if (dx, dy) in take:
                        continue
                    cands = [(dx + 1, dy + 1), (dx + 1, dy - 1), (dx - 1, dy + 1), (dx - 1, dy - 1)]
                    take[(dx, dy)] = min(cands, key=lambda c, t=(dx, dy): abs(dep[t] - dep[c]))  # first of the ties
        for a in range(0, m, 2):  # second pass: whatever is left goes to the owner in + direction
            for b in range(0, m, 2):
                for t in ((a - 1, b), (a, b - 1), (a - 1, b - 1)):
                    if t[0] >= 0 and t[1] >= 0 and t not in take:
                        take[t] = (a, b)
        assert len(take) == m * m
        new_members, new_dep = {}, {}
        for t, o in take.items():
            key = (o[0] // 2, o[1] // 2)
            new_members.setdefault(key, []).extend(members[t])
            new_dep[key] = min(new_dep.get(key, 1e38), dep[t])
        members, dep, n = new_members, new_dep, m // 2
        out.append(({k: bbox(v) for k, v in members.items()}, dict(dep), {k: list(v) for k, v in members.items()}))
    return out


@pytest.mark.parametrize("diagonal,flat", [("paper", False), ("nearest", False), ("paper", True)])
def test_microrects_against_reference_and_invariants(device, diagonal, flat):
    """The kernels against the pure-Python merge; ``flat``: blocks of one depth up to float32
    rounding (a few ulps), where the tie tolerance decides the partners."""
    n = 32
    d = _random_map(n, 5)
    if flat:
        rng = np.random.default_rng(6)
        d = np.kron(rng.random((n // 4, n // 4)), np.ones((4, 4))).astype(np.float32)
        d *= (1.0 + 2.4e-7 * rng.integers(-2, 3, (n, n))).astype(np.float32)
        assert len(np.unique(d)) > 2 * (n // 4) ** 2  # the rounding is there
    mr = build_microrects(wp.array(d, dtype=float, device=device), device, diagonal)
    ref = _microrects_reference(d, 5, diagonal)
    partial_cover = 0
    for i in range(1, 6):
        ext, dep = mr.level(i)
        rext, rdep, rmem = ref[i - 1]
        m = n >> i
        seen = np.zeros((n, n), int)
        for a in range(m):
            for b in range(m):
                x0, y0, x1, y1 = ext[b, a]
                assert (x0, y0, x1, y1) == rext[(a, b)]
                assert dep[b, a] == np.float32(rdep[(a, b)])
                # the extent holds its reference point and no other level-i one
                rx, ry = a << i, b << i
                assert x0 <= rx <= x1 and y0 <= ry <= y1
                xs = [x for x in range(x0, x1 + 1) if x % (1 << i) == 0]
                ys = [y for y in range(y0, y1 + 1) if y % (1 << i) == 0]
                assert xs == [rx] and ys == [ry]
                # the depth is the minimum of what it covers (its members), never above a texel in its extent's members
                mem = rmem[(a, b)]
                assert dep[b, a] == min(d[y, x] for x, y in mem)
                for x, y in mem:
                    seen[y, x] += 1
                partial_cover += (x1 - x0 + 1) * (y1 - y0 + 1) > len(mem)
        assert np.all(seen == 1)  # the members partition the map: no occluder is lost
    assert partial_cover > 0  # some extents are bounding boxes of non-rectangular merges


def _rotated_plate_map(n: int, angle: float) -> np.ndarray:
    """A square caster (depth 0.3) turned ``angle`` degrees over a ground (depth 0.9, with a slight slope)."""
    y, x = np.mgrid[0:n, 0:n] + 0.5
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    u, v = (x - n / 2) * c + (y - n / 2) * s, -(x - n / 2) * s + (y - n / 2) * c
    d = 0.9 + 0.001 * x / n
    d[(np.abs(u) < 0.3 * n) & (np.abs(v) < 0.3 * n)] = 0.3
    return d.astype(np.float32)


@pytest.mark.parametrize("angle", [0.0, 30.0])
def test_nearest_diagonal_keeps_the_casters_depth_off_the_ground(device, angle):
    """Where §5.2's diagonal rule puts a caster's depth on the ground. In the second pass a
    diagonal that the first pass of the retained microrect at its -x-y corner leaves is merged,
    whatever its depth, into the one at its +x+y corner: a ground microrect next to the plate's
    edge takes a plate diagonal and with it the plate's (minimum) depth, and its extent, mostly
    ground, then occludes at the plate's depth. With ``diagonal="nearest"`` (not the paper's) the
    diagonal goes to the neighbour of nearest depth. Measured on a 128² map, ground texels covered
    by microrects at the plate's depth (paper / nearest / micropatches): 0°: level 3 180 / 12 /
    624, level 4 484 / 220 / 3440; 30°: level 3 1139 / 657 / 1524, level 4 2768 / 1970 / 3316."""
    n = 128
    d = _rotated_plate_map(n, angle)
    plate = d < 0.5
    wrong = {}
    for rule in ("paper", "nearest"):
        mr = build_microrects(wp.array(d, dtype=float, device=device), device, rule)
        wrong[rule] = []
        for i in (3, 4):
            ext, dep = mr.level(i)
            cov = np.zeros((n, n), bool)
            for y, x in zip(*np.nonzero(dep < 0.5)):
                x0, y0, x1, y1 = ext[y, x]
                cov[y0:y1 + 1, x0:x1 + 1] = True
            assert cov[plate].all()  # no caster texel is lost
            wrong[rule].append(int((cov & ~plate).sum()))
    for i, lev in enumerate((3, 4)):
        # the level-i micropatches: every block with a plate texel, at its minimum depth
        c = 1 << lev
        patch = int((plate.reshape(n // c, c, n // c, c).any(axis=(1, 3))).sum()) * c * c - int(plate.sum())
        assert wrong["nearest"][i] < 0.9 * wrong["paper"][i]
        assert wrong["nearest"][i] < 0.85 * patch  # the nearest-depth microrects fit better than micropatches


_ground_error = box_plane_ground_error


def test_flat_occluder_rounding_does_not_choose_merge_partners(device):
    """A flat square occluder over a flat ground whose rasterized depths vary by float32 rounding
    (1e-7 relative): with an exact comparison the rounding picks each merge partner inside the
    occluder, the first-pass extents turn irregular, their diagonals fail the containment test and
    §5.2's second pass hands them, whatever their depth, to the ground microrect at their +x+y
    corner, which then occludes at the occluder's depth a cell beyond its edge. Counting
    differences within ``tie`` as equal keeps the noise-free merge. Measured on a 256² map, ground
    texels covered at the occluder's depth at levels 3 / 4 / 5: exact 1144 / 5327 / 14296, tie
    41 / 922 / 2060 (as without the noise), micropatches 1680 / 3536 / 9680."""
    n = 256
    rng = np.random.default_rng(1)
    plate = np.zeros((n, n), bool)
    plate[93:201, 81:181] = True
    clean = np.where(plate, 0.3, 0.9).astype(np.float32)
    noisy = (clean * (1.0 + 1e-7 * rng.standard_normal((n, n)))).astype(np.float32)

    def ground_covered(d, tie):
        mr = build_microrects(wp.array(d, dtype=float, device=device), device, "paper", tie)
        out = []
        for i in (3, 4, 5):
            ext, dep = mr.level(i)
            cov = np.zeros((n, n), bool)
            for y, x in zip(*np.nonzero(dep < 0.5)):
                x0, y0, x1, y1 = ext[y, x]
                cov[y0:y1 + 1, x0:x1 + 1] = True
            assert cov[plate].all()
            out.append(int((cov & ~plate).sum()))
        return out

    exact, tied, clean_tied = ground_covered(noisy, 0.0), ground_covered(noisy, 1e-6), ground_covered(clean, 1e-6)
    assert tied == clean_tied == ground_covered(clean, 0.0)
    for i, lev in enumerate((3, 4, 5)):
        c = 1 << lev
        patch = int(plate.reshape(n // c, c, n // c, c).any(axis=(1, 3)).sum()) * c * c - int(plate.sum())
        assert tied[i] < 0.3 * patch
    assert exact[2] > 1.2 * (int(plate.reshape(8, 32, 8, 32).any(axis=(1, 3)).sum()) * 1024 - int(plate.sum()))
    assert all(e > 4 * t for e, t in zip(exact, tied))


def test_microrects_beat_micropatches_on_an_aligned_plate(device):
    """Fig. 12's claim on the simplest case: a square plate with its edges along the light view's
    axes, parallel to the ground and to a square rect light, b_mo = 3 (levels 4 and 5), against
    the exact visible fraction. Two causes of error are separated: the gather (``budget`` reads the
    (b+1)² cells over the search area and misses extents that reach into it from the +x / +y
    cells: under-occlusion) and the rounding of the plate's depth deciding the merge partners
    (``microrect_tie=0``: over-occlusion). Measured at 160 x 120, penumbra MAE (mean positive
    error): micropatches 0.050 (0.000), microrects 0.031 (0.003), gather=budget 0.045 (0.020),
    microrect_tie=0 0.119 (0.001), both 0.125 (0.022)."""
    from wsoft.metrics.exact import parallel_rect_exact
    from wsoft.stages.ssm_cases import stage_file

    scene = wsoft.load_scene(stage_file("plate_aligned"))
    kw = {"width": 160, "height": 120, "device": device, "budget": 3.0}
    err = {}
    for label, p in (("patch", {"occluder": "micropatch"}), ("rect", {"occluder": "microrect"}),
                     ("budget", {"occluder": "microrect", "gather": "budget"}), ("exact", {"occluder": "microrect", "microrect_tie": 0.0})):
        f = wsoft.render(scene, "ssm", **kw, **p)
        g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
        ex = parallel_rect_exact(f["P.X"], f["P.Y"], 4.0, 1.0, 1.2, 0.75)
        pen = g & (ex > 0.01) & (ex < 0.99)
        assert pen.sum() > 1000
        e = (f.V - ex)[pen]
        err[label] = (float(np.abs(e).mean()), float(np.clip(e, 0, None).mean()))
        if label == "rect":
            assert set(f.counters()["levels_used"]) == {"4", "5"}
    assert err["rect"][0] < 0.75 * err["patch"][0]
    assert err["rect"][1] < 0.006 and err["budget"][1] > 0.012  # the +x / +y extents are read
    assert err["exact"][0] > 2.5 * err["rect"][0]  # the rounding is there, and the tie keeps it out


def test_microrects_fit_a_planar_occluder_better_at_coarse_levels(device):
    """§5's point on the simplest occluder: at a coarse level (b_mo = 3, level 4 here) a
    micropatch covers its whole aligned block at the block's minimum depth, so the square
    occluder's shadow grows to the block boundaries; the microrects merge only the occluder's
    texels and keep its edges. Measured: MAE 0.0073 (micropatch) vs 0.0012 (microrect)."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    kw = {"width": 160, "height": 120, "device": device, "budget": 3.0, "blend": False}
    patch = wsoft.render(scene, "ssm", occluder="micropatch", **kw)
    rect = wsoft.render(scene, "ssm", occluder="microrect", **kw)
    assert set(rect.counters()["levels_used"]) == {"4"}
    e_patch, e_rect = _ground_error(patch)[0], _ground_error(rect)[0]
    assert e_rect < 0.5 * e_patch and e_rect < 0.004


@pytest.mark.parametrize("visibility", ["area", "bitmask"])
def test_exact_on_parallel_rectangles_at_level_0(device, visibility):
    """Level 0, b_mo = inf: the micropatches of one planar occluder parallel to the light abut
    when backprojected; the only error is the texels' quantisation of the occluder's edge
    (1024^2 map) and, for the bitmask, the 32 x 32 light samples."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "ssm", width=128, height=96, device=device, budget=INF, visibility=visibility, bitmask_size=32, pattern="regular")
    mae, mae_pen, mx = _ground_error(f)
    assert mae < 0.001 and mae_pen < 0.012 and mx < 0.04
    assert set(f.counters()["levels_used"]) == {"0"}


def test_bitmask_matches_area_without_overlaps(device):
    """One planar occluder: projections do not overlap, so the bitmask's count equals the summed
    area up to the sample spacing."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    kw = {"width": 96, "height": 72, "device": device, "budget": INF}
    area = wsoft.render(scene, "ssm", visibility="area", **kw)
    bits = wsoft.render(scene, "ssm", visibility="bitmask", bitmask_size=32, pattern="regular", **kw)
    pen = (area.V > 0.02) & (area.V < 0.98)
    assert pen.sum() > 50
    assert np.abs(area.V - bits.V).max() < 2.5 / 32


def test_bitmask_avoids_over_occlusion_of_overlaps(device):
    """Many overlapping layers (a plant): area accumulation over-occludes, the bitmask does not."""
    from wsoft.bench.harness import reference

    ref = reference("penumbra_ramp", width=64, height=48, light=None, samples=64, device=device)
    scene = wsoft.load_scene(scene_path("penumbra_ramp.usda"))
    kw = {"width": 64, "height": 48, "device": device, "budget": INF, "shadow_map_size": 512}
    a = wsoft.render(scene, "ssm", visibility="area", **kw)
    b = wsoft.render(scene, "ssm", visibility="bitmask", **kw)
    cov = ref["A"] > 0
    assert np.mean(np.abs(b.V - ref["V"])[cov]) <= np.mean(np.abs(a.V - ref["V"])[cov]) + 1e-4


def _tilted_plank():
    """A plank rising from 0.2 to 2.2 over a ground plane under a rect light: its penumbra widens
    along it, so the level a budget asks for changes inside one penumbra."""
    from conftest import add_camera, add_quad, add_rect_light, make_stage
    from pxr import UsdGeom

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 6)
    m = UsdGeom.Mesh.Define(st, "/World/Plank")
    m.CreatePointsAttr([(-2.5, -0.6, 0.2), (2.5, -0.6, 2.2), (2.5, 0.6, 2.2), (-2.5, 0.6, 0.2)])
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    m.CreateDoubleSidedAttr(True)
    add_rect_light(st, "/World/Light", (0, 0, 4), 1.5, 1.5)
    add_camera(st, "/World/Cam", (0, -0.01, 9), (0, 0, 0), focal=14)
    return wsoft.load_scene(st)


def test_blending_makes_visibility_continuous_across_levels(device):
    """Neighbouring ground pixels whose budget level ceil(l) differs: without blending V jumps
    there (the transition artifact of Fig. 1a); the smoothed LOQ and blending bound the jump."""
    from wsoft.pipeline import build_graph
    from wsoft.techniques import create

    scene = _tilted_plank()
    w, h = 160, 120
    jumps = {}
    for blend in (False, True):
        built = build_graph(scene, create("ssm", {"budget": 3, "blend": blend}), width=w, height=h, device=device)
        res, _ = built.ctx.graph.execute(built.requested, device, keep=["ssm_search[ssm:Light]"])
        s, ch = res["ssm_search[ssm:Light]"], res["channels[ssm]"]
        level = np.ceil(s.loq_raw.numpy().reshape(h, w) - 1e-6)
        g = (ch["A"] > 0) & (np.abs(ch["P.Z"]) < 1e-3) & (s.status.numpy().reshape(h, w) == 2)
        change = g[:, 1:] & g[:, :-1] & (level[:, 1:] != level[:, :-1])
        assert change.sum() >= 20  # the interesting case happens
        jumps[blend] = np.abs(np.diff(ch["V"], axis=1))[change]
    assert np.median(jumps[False]) > 3 * np.median(jumps[True])
    assert np.quantile(jumps[True], 0.99) < 0.25 and np.median(jumps[True]) < 0.06


def test_msaa_resolve_hand_built_3x3():
    """3 x 3 pixels, 2 samples each. The centre pixel's second sample lies on another surface
    (camera depth 5 instead of 2): it takes the visibility of the 4-neighbour whose first sample's
    depth is closest (the right one, depth 5.1), not the pixel's own."""
    w = h = 3
    vis_pix = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9], np.float32)
    rep = np.array([2.0, 2.0, 2.0, 2.0, 2.0, 5.1, 2.0, 7.0, 2.0], np.float32)
    s0 = rep.copy()
    s1 = rep.copy()
    s1[4] = 5.0  # centre: a second surface
    s1[0] = 2.01  # corner: same surface within tau
    s1[8] = 0.0  # background sample
    dist = np.concatenate([s0, s1])
    prim = np.ones(18, np.int32)
    prim[9 + 8] = -1
    dev = "cpu"
    rid = wp.array(np.arange(9, dtype=np.int32), dtype=wp.int32, device=dev)  # every pixel's visibility is on its first sample
    f3 = lambda: wp.zeros(18, dtype=wp.vec3, device=dev)  # noqa: E731
    f2 = lambda: wp.zeros(18, dtype=wp.vec2, device=dev)  # noqa: E731
    gb = GBuffer(w, h, 2, f3(), f3(), wp.array(dist, dtype=float, device=dev), wp.array(prim, dtype=wp.int32, device=dev), f2(), f2())
    args = (wp.array(vis_pix, dtype=float, device=dev), rid, gb, 0.01)
    out = msaa_resolve(*args, True, dev).numpy()
    assert np.allclose(out[:9], vis_pix)  # first samples: their pixel's
    assert out[9 + 4] == pytest.approx(0.6)  # the right neighbour (5.1) is closest to 5.0; below (7.0) is not
    assert out[9 + 0] == pytest.approx(0.1)  # within tau: its own pixel
    assert out[9 + 8] == 1.0  # background
    single = msaa_resolve(*args, False, dev).numpy()
    assert single[9 + 4] == pytest.approx(0.5)  # without interpolation: the pixel's


def test_msaa_interpolation_close_to_per_sample(device):
    scene = wsoft.load_scene(scene_path("contact.usda"))
    kw = {"width": 64, "height": 48, "device": device, "pixel_samples": 4, "budget": 8}
    brute = wsoft.render(scene, "ssm", msaa="per_sample", **kw)
    interp = wsoft.render(scene, "ssm", msaa="interpolate", **kw)
    cov = brute["A"] > 0
    assert np.mean(np.abs(interp.V - brute.V)[cov]) < 0.02
    assert brute.counters()["receivers"] > 3 * interp.counters()["receivers"]


@pytest.mark.parametrize("params", [
    {"occluder": "microquad", "visibility": "area", "structure": "hsm"},
    {"occluder": "microrect", "pattern": "random", "bitmask_size": 8, "structure": "mssm"},
    {"occluder": "micropatch", "budget_map": "radial", "budget": 12, "blend": False},
])
@pytest.mark.parametrize("file", ["contact.usda", "multi_light.usda"])
def test_finite_and_in_range(device, params, file):
    """Contact shadows, and rect / disk / sphere / distant lights (multi_light)."""
    scene = wsoft.load_scene(scene_path(file))
    f = wsoft.render(scene, "ssm", width=48, height=36, device=device, shadow_map_size=512, **params)
    for name in [k for k in f.channels if k.startswith("V")] + ["R", "G", "B"]:
        assert np.all(np.isfinite(f[name]))
    assert f.V.min() >= 0.0 and f.V.max() <= 1.0
    assert f.V[f["A"] > 0].min() < 0.5  # there is shadow
    assert f.counters()["backprojecting_fraction"] > 0


@pytest.mark.parametrize("light", ["Rect", "Disk", "Sphere", "Sun"])
def test_each_light_kind_against_reference(device, light):
    """multi_light: tilted rect and disk lights, a sphere light and a 2-degree sun. Receivers tilted
    in the light's view see their own surface in the map; they must not be taken for umbra (the
    umbra test compares with the nearest depth of the receiver's tangent plane over the area)."""
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    kw = {"width": 96, "height": 72, "device": device, "light": light}
    ref = wsoft.render(scene, "reference", samples=64, **kw)
    f = wsoft.render(scene, "ssm", budget=INF, **kw)
    cov = ref["A"] > 0
    d = (f.V - ref.V)[cov]
    assert abs(d.mean()) < 0.02 and np.abs(d).mean() < 0.025  # before the fix: -0.11 (disk), -0.19 (sphere), -0.11 (sun)
    c = f.stats["counters"]["techniques"]["ssm"]  # a cube map's faces count per face (Sphere/+x, ...)
    assert max(v.get("backprojecting_fraction", 0.0) for k, v in c.items() if k == light or k.startswith(light + "/")) > 0.02


def test_budget_map_from_exr(tmp_path):
    from wsoft.io import write_exr

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    b = np.full((12, 16), 4.0, np.float32)
    b[:, 8:] = 64.0
    path = str(tmp_path / "budget.exr")
    write_exr(path, {"budget": b})
    f = wsoft.render(scene, "ssm", width=64, height=48, device="cpu", budget=64, budget_map=path, blend=False)
    uniform = wsoft.render(scene, "ssm", width=64, height=48, device="cpu", budget=64, blend=False)
    left = np.s_[:, :28]
    assert not np.allclose(f.V[left], uniform.V[left])  # the left half used a coarser level
    assert np.allclose(f.V[:, 36:], uniform.V[:, 36:], atol=1e-6)  # the right half did not


def test_bad_inputs(tmp_path):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    kw = {"width": 8, "height": 8, "device": "cpu"}
    with pytest.raises(wsoft.ParameterError, match="occluder 'microtri' is not one of"):
        wsoft.render(scene, "ssm", occluder="microtri", **kw)
    with pytest.raises(wsoft.ParameterError, match="power of two"):
        wsoft.render(scene, "ssm", shadow_map_size=1000, **kw)
    with pytest.raises(wsoft.ParameterError, match="pattern 'hex'"):
        wsoft.render(scene, "ssm", pattern="hex", **kw)
    missing = str(tmp_path / "nope.exr")
    with pytest.raises(wsoft.ParameterError, match="nope.exr"):
        wsoft.render(scene, "ssm", budget_map=missing, **kw)
    bad = tmp_path / "bad.exr"
    bad.write_text("not an exr")
    with pytest.raises(wsoft.ParameterError, match="bad.exr"):
        wsoft.render(scene, "ssm", budget_map=str(bad), **kw)
    with pytest.raises(wsoft.ParameterError, match="no parameter"):
        wsoft.render(scene, "ssm", budgett=3, **kw)


def test_point_light_is_rejected():
    from conftest import add_camera, add_quad, make_stage
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 5)
    add_quad(st, "/World/O", (0, 0, 1), 0.5)
    light = UsdLux.SphereLight.Define(st, "/World/Point")
    light.CreateRadiusAttr(0.0)
    UsdGeom.XformCommonAPI(light).SetTranslate(Gf.Vec3d(0, 0, 3))
    add_camera(st, "/World/Cam", (0, -4, 4), (0, 0, 0))
    with pytest.raises(wsoft.ParameterError, match="/World/Point"):
        wsoft.render(wsoft.load_scene(st), "ssm", width=8, height=8, device="cpu")


def test_cli_missing_budget_map_is_one_line(tmp_path):
    """From the command line: exit code 2, one line naming the file, no traceback."""
    from conftest import ROOT, wsoft_cli

    missing = str(tmp_path / "budget.exr")
    p = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "ssm", "--set", f"budget_map={missing}", "--width", "8", "--height", "8",
                  "--device", "cpu", "--out", str(tmp_path / "o.exr"), cwd=ROOT)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("wsoft: error")]
    assert len(lines) == 1 and missing in lines[0] and "not found" in lines[0]


def test_table1_rows_and_report(tmp_path):
    """``wsoft bench ssm-table1``'s rows carry structure, size, build_ms and memory_mb; the report puts the paper beside them."""
    from wsoft.bench import ssm_table1

    rows = []
    for structure in ("mssm", "ysm"):
        case = {"kind": "build", "scene": "box_plane", "structure": structure, "size": 256, "ysm_size": 64, "device": "cpu"}
        row = ssm_table1.run_case(case, {})
        assert {"structure", "size", "build_ms", "memory_mb"} <= set(row) and row["build_ms"] > 0
        rows.append(row | {"case": case, "machine": {}})
    assert rows[0]["memory_mb"] > 4 * rows[1]["memory_mb"]  # MSSM (9 scales of 256^2) against HSM + 6 scales of 64^2
    md = tmp_path / "t1.md"
    ssm_table1.report(rows, md, {"quick": True, "command": "wsoft bench ssm-table1 --quick"})
    text = md.read_text()
    assert "wsoft bench ssm-table1 --quick" in text and "YSM at least 4×" in text


def test_microrect_gather_reads_every_extent_that_reaches_the_area(device):
    """A level-j microrect's extent lies within one cell of its reference point, so the cells
    over the search area plus one on its +x and +y sides hold every microrect that can reach it
    (``gather=extent``, at most (ceil(b)+2)² a level, those whose extent misses the area skipped);
    ``gather=budget`` reads the (ceil(b)+1)² cells over the area, as micropatches, and misses the
    extents reaching in from the +x / +y cells. Checked on foliage (fig1_plant) and on a solid
    plate, where the budget gather under-occludes and the extent gather does not."""
    from wsoft.stages.ssm_cases import stage_file

    b = 3.0
    kw = {"width": 96, "height": 72, "device": device, "budget": b, "blend": False, "occluder": "microrect"}
    for scene in (wsoft.load_scene(scene_path("fig1_plant.usdc")), wsoft.load_scene(stage_file("plate_rotated"))):
        extent = wsoft.render(scene, "ssm", **kw)
        budget = wsoft.render(scene, "ssm", gather="budget", **kw)
        assert 0 < budget.counters()["occluders_max"] <= (int(np.ceil(b)) + 1) ** 2
        assert 0 < extent.counters()["occluders_max"] <= (int(np.ceil(b)) + 2) ** 2
        assert extent.counters()["occluders_mean"] > budget.counters()["occluders_mean"]
        assert np.all(extent.V <= budget.V + 1e-6)  # a superset of the same micro-occluders
    ref = wsoft.render(scene, "reference", width=96, height=72, device=device, samples=64)
    pen = (ref["A"] > 0) & (ref.V > 0.01) & (ref.V < 0.99)
    assert pen.sum() > 300
    missed = (budget.V - extent.V)[pen]
    assert (missed > 0.05).sum() > 20  # the budget gather misses occluders on the plate's penumbra
    assert float((extent.V - ref.V)[pen].mean()) < float((budget.V - ref.V)[pen].mean())


def test_microrects_beat_micropatches_on_a_rotated_plate(device):
    """On the plate turned 30° in the light's view, at b_mo = 3 and on the same search areas and
    levels, microrects (both diagonal rules) beat micropatches on the reference's penumbra; the
    nearest-depth diagonal (not the paper's) keeps less ground under the plate's depth where the
    bounding-box union overhangs the diagonal edges (96 x 72, 64 spp: penumbra MAE 0.198
    micropatches, 0.125 paper microrects, 0.097 nearest)."""
    from wsoft.stages.ssm_cases import stage_file

    scene = wsoft.load_scene(stage_file("plate_rotated"))
    kw = {"width": 96, "height": 72, "device": device, "budget": 3.0}
    ref = wsoft.render(scene, "reference", width=96, height=72, device=device, samples=64)
    pen = (ref["A"] > 0) & (ref.V > 0.01) & (ref.V < 0.99)
    err = {}
    for label, p in (("patch", {"occluder": "micropatch"}), ("paper", {"occluder": "microrect"}),
                     ("nearest", {"occluder": "microrect", "microrect_diagonal": "nearest"})):
        err[label] = float(np.abs(wsoft.render(scene, "ssm", **kw, **p).V - ref.V)[pen].mean())
    assert err["paper"] < 0.8 * err["patch"] and err["nearest"] < 0.9 * err["paper"]


def test_occluder_types_share_search_areas_and_levels(device):
    """The region grown to the micro-occluders' support (§6) decides lit/umbra
    only; the search area itself drives the refinement and the level. Micropatch and microrect
    runs then search the same areas (on fig1_plant at b = 3 both backproject 0.35 of the receivers at
    240 x 180)."""
    scene = wsoft.load_scene(scene_path("fig1_plant.usdc"))
    kw = {"width": 96, "height": 72, "device": device, "budget": 3.0}
    patch = wsoft.render(scene, "ssm", occluder="micropatch", **kw).counters()
    rect = wsoft.render(scene, "ssm", occluder="microrect", **kw).counters()
    # the same areas, up to the few receivers the microrects' wider grown region classifies otherwise
    assert rect["search_width_mean_texels"] == pytest.approx(patch["search_width_mean_texels"], rel=0.01)
    assert abs(rect["backprojecting_fraction"] - patch["backprojecting_fraction"]) < 0.03
    assert rect["backprojecting_fraction"] < 0.5
    flat = [wsoft.render(scene, "ssm", occluder=o, overprecision=False, **kw).counters() for o in ("micropatch", "microrect")]
    assert flat[0]["search_width_mean_texels"] == flat[1]["search_width_mean_texels"]  # no growth: identical


def test_table2_denominators_are_reported(device):
    """The backprojecting share over all pixels beside the share over covered
    pixels, and the mean search width in texels."""
    scene = wsoft.load_scene(scene_path("fig1_plant.usdc"))
    c = wsoft.render(scene, "ssm", width=64, height=48, device=device, budget=math.inf).counters()
    assert c["samples"] == 64 * 48 and c["receivers"] < c["samples"]
    assert c["backprojecting_fraction_all_pixels"] == pytest.approx(c["backprojecting_fraction"] * c["receivers"] / c["samples"])
    assert c["search_width_mean_texels"] > 10
