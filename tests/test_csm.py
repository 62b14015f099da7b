"""``csm``: cascaded shadow maps for a distant light. Practical splits follow their closed form;
SDSM's reduction bounds every sample (against NumPy on the same points) and its cascades' windows
hold every sample of their depth range; stable cascades keep their texel grid under a camera move
smaller than a texel and give a static receiver the same V after a camera translation, where
fitted ones do not; the blend band keeps the error near the splits close to the error away from
them; parameters are validated; local lights are declined; on city/Sun it beats a single ``pcf``
map of the same size."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp
from pxr import Sdf, UsdLux

import wsoft
from wsoft.accel.depth_reduce import cascade_bounds, sample_depth_range
from wsoft.errors import ParameterError
from wsoft.lightspace.cascades import blend_band, cascade_ranges, log_splits, practical_splits, slice_corners, slice_sphere
from wsoft.lightspace.view import to_frame
from wsoft.raster.gbuffer import bake_gbuffer
from wsoft.scene.types import Camera
from wsoft.stages.builders import add_box, add_camera, add_quad, add_rect_light, add_sun, make_stage
from wsoft.techniques import get_technique
from wsoft.techniques.csm import CSM, camera_frame, cascade_weight, fit_cascades

W, H = 160, 120
QUICK = {"map_size": 256}


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A camera's to-world matrix at ``eye`` looking at ``target`` (the camera looks down its −Z)."""
    eye = np.asarray(eye, np.float64)
    z = eye - np.asarray(target, np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, eye
    return m


def posts_stage(rect: bool = False, unlinked: tuple[str, ...] = ()):
    """A 80 x 80 ground with a 9 x 9 field of posts (1 x 1 x 4, 8 apart), a sun 2 degrees wide from
    about 35 degrees off the zenith, a camera low over one edge looking across (depths ~10 to ~90);
    ``rect``: a rect light as well; ``unlinked``: prims excluded from the sun's ``collection:shadowLink``."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0.0, 0.0, 0.0), 40.0)
    for i in range(9):
        for j in range(9):
            x, y = -32.0 + 8.0 * i, -32.0 + 8.0 * j
            add_box(st, f"/World/Post_{i}_{j}", (x - 0.5, y - 0.5, 0.0), (x + 0.5, y + 0.5, 4.0))
    sun = add_sun(st, "/World/Sun", 2.0, toward=(0.5, 0.35, 1.0))
    for path in unlinked:
        UsdLux.LightAPI(sun.GetPrim()).GetShadowLinkCollectionAPI().GetExcludesRel().AddTarget(Sdf.Path(path))
    if rect:
        add_rect_light(st, "/World/Rect", (0.0, 0.0, 20.0), 2.0, 2.0)
    add_camera(st, "/World/Cam", (0.0, -48.0, 10.0), (0.0, 0.0, 0.0), focal=18.0, clip=(0.5, 500.0))
    return wsoft.load_scene(st)


@pytest.fixture(scope="module")
def posts():
    return posts_stage()


# --------------------------------------------------------------------------- splits


@pytest.mark.parametrize("lam", [0.0, 0.3, 0.5, 1.0])
def test_practical_splits_match_the_closed_form(lam):
    n, f, k = 0.5, 400.0, 4
    s = practical_splits(n, f, k, lam)
    for i in range(k + 1):
        want = lam * n * (f / n) ** (i / k) + (1.0 - lam) * (n + (f - n) * i / k)
        assert s[i] == pytest.approx(want, rel=1e-12)
    assert np.all(np.diff(s) > 0)
    assert log_splits(2.0, 32.0, 4) == pytest.approx([2.0, 4.0, 8.0, 16.0, 32.0])  # SDSM: logarithmic over the sampled range


def test_blend_ranges_overlap_by_the_band():
    s = np.array([1.0, 3.0, 7.0, 15.0])
    b = blend_band(s, 0.25)
    assert b == pytest.approx([0.5, 1.0, 0.0])
    r = cascade_ranges(s, b)
    assert r == pytest.approx(np.array([[1.0, 3.0], [2.5, 7.0], [6.0, 15.0]]))


def test_slice_sphere_holds_the_slice_and_ignores_the_camera_direction():
    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b = sorted(rng.uniform(0.1, 50.0, 2))
        tx, ty = rng.uniform(0.1, 1.5, 2)
        c, r = slice_sphere(a, b, tx, ty)
        m = look_at(rng.normal(size=3) * 10, rng.normal(size=3) * 10)
        axes = m[:3, :3].copy()
        axes[:, 2] *= -1.0  # forward
        corners = slice_corners(m[:3, 3], axes, a, b, (-tx, tx, -ty, ty))
        centre = m[:3, 3] + axes[:, 2] * c
        assert np.linalg.norm(corners - centre, axis=1).max() <= r * (1 + 1e-9)


def test_counters_record_the_practical_splits(posts):
    f = wsoft.render(posts, ("csm", {**QUICK, "partition": "practical", "split_lambda": 0.6}), width=W, height=H)
    c = f.stats["counters"]["techniques"]["csm"]["Sun"]
    lo, hi = c["sample_depth_range"]
    near = min(max(0.5, 1e-6 * hi), lo)  # the camera's near clipping plane (0.5)
    assert c["splits"] == pytest.approx(practical_splits(near, hi, 4, 0.6).tolist())
    assert c["map_bytes"] == c["cascades_drawn"] * 256 * 256 * 4
    assert len(c["texel_size"]) == 4 and all(t >= 0 for t in c["texel_size"])


# --------------------------------------------------------------------------- SDSM


def test_reduction_matches_numpy():
    rng = np.random.default_rng(7)
    n = 20000
    pos = rng.uniform(-10, 10, (n, 3)).astype(np.float32)
    prim = np.where(rng.uniform(size=n) < 0.2, -1, 0).astype(np.int32)
    gb = bake_gbuffer(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n, np.int32), None, "cpu")
    gpos = gb.pos
    import warp as wp

    gprim = wp.array(np.pad(prim, (0, gb.count - n), constant_values=-1), dtype=wp.int32, device="cpu")
    eye, fwd = np.array([0.0, -30.0, 5.0]), np.array([0.0, 1.0, -0.1]) / math.hypot(1.0, 0.1)
    d = (pos.astype(np.float64) - eye) @ fwd
    cov = prim >= 0
    count, lo, hi = sample_depth_range(gpos, gprim, eye, fwd)
    assert count == cov.sum() and lo == pytest.approx(d[cov].min()) and hi == pytest.approx(d[cov].max())
    axes = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    anchor = np.array([1.0, 2.0, 3.0])
    ranges = np.array([[lo, 22.0], [20.0, 30.0], [29.0, hi], [1e5, 2e5]])
    cnt, blo, bhi = cascade_bounds(gpos, gprim, eye, fwd, anchor, axes, ranges)
    v = to_frame(pos.astype(np.float64), anchor, axes)
    for k, (a, b) in enumerate(ranges):
        sel = cov & (d >= a) & (d <= b)
        assert cnt[k] == sel.sum()
        if sel.any():
            assert blo[k] == pytest.approx(v[sel].min(axis=0), abs=1e-5) and bhi[k] == pytest.approx(v[sel].max(axis=0), abs=1e-5)
    assert cnt[3] == 0 and np.all(np.isinf(blo[3]))


@pytest.mark.parametrize("stable", [True, False])
@pytest.mark.parametrize("partition", ["sdsm", "practical"])
def test_every_sample_lies_in_its_cascades_windows(posts, stable, partition):
    """The frame's visible points (from a render) fitted into cascades: each point lies inside the
    window of every cascade whose depth range (band included) holds it."""
    f = wsoft.render(posts, ("hard", {"shadow_map_size": 256}), width=W, height=H)
    cov = f["A"] > 0
    pos = np.stack([f["P.X"][cov], f["P.Y"][cov], f["P.Z"][cov]], axis=1)
    n = len(pos)
    gb = bake_gbuffer(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n, np.int32), None, "cpu")
    cam = posts.cameras[0]
    sun = next(l for l in posts.lights if l.path.endswith("Sun"))
    params = CSM.make_params({**QUICK, "stable": stable, "partition": partition})
    counters = {}
    cs = fit_cascades(SimpleNamespace(camera=cam, origin=None, scene=posts), sun, gb, params, counters)
    eye, fwd = camera_frame(cam)
    d = (pos - eye) @ fwd
    ranges = cascade_ranges(cs.splits, cs.band)
    assert sum(counters["cascade_samples"]) >= n
    for k, view in enumerate(cs.views):
        sel = (d >= ranges[k, 0]) & (d <= ranges[k, 1])
        if view is None:
            assert not sel.any()
            continue
        x, y = view.texel_coords(pos[sel])
        assert x.min() >= 0 and y.min() >= 0 and x.max() <= view.width and y.max() <= view.height, k
        vz = view.to_view(pos[sel])[:, 2]
        assert vz.min() >= view.near and vz.max() <= view.far


# --------------------------------------------------------------------------- stability


def _ortho_down(cx: float, cy: float) -> Camera:
    m = look_at((cx, cy, 30.0), (cx, cy, 0.0), up=(0.0, 1.0, 0.0))
    return Camera("/Ortho", m, orthographic=True, tan_half=(16.0, 12.0), clip=(0.1, 100.0))


@pytest.mark.parametrize("stable", [True, False])
def test_stable_cascades_do_not_shimmer_under_a_camera_translation(posts, stable):
    """An orthographic camera looking down, moved sideways by one pixel (0.2 units, below the
    stable cascades' texel): the same world points, the same depths; with stable cascades their V
    is identical, pixel for pixel (shifted by one); fitted cascades move their texel grids and
    change V at some shadow edges."""
    px = 32.0 / W
    t = ("csm", {**QUICK, "stable": stable, "filter": "pcf"})
    a = wsoft.render(posts, t, width=W, height=H, camera=_ortho_down(1.3, 0.7), light="Sun")
    b = wsoft.render(posts, t, width=W, height=H, camera=_ortho_down(1.3 + px, 0.7), light="Sun")
    ta = a.stats["counters"]["techniques"]["csm"]["Sun"]["texel_size"]
    va, vb = a.V[:, 1:], b.V[:, :-1]  # b's pixel x is a's x + 1
    pen = (va > 0.0) & (va < 1.0)
    assert pen.sum() > 50  # penumbra pixels to compare
    if stable:
        assert np.array_equal(va, vb), int((va != vb).sum())
    else:
        assert (va != vb).sum() > 0


def test_stable_texel_grid_under_a_sub_texel_move(posts):
    """Fitted from the same samples seen by a camera 0.3 texel further along, every stable cascade
    keeps its texel size and its texel corners on the same grid (whole texels apart)."""
    sun = next(l for l in posts.lights if l.path.endswith("Sun"))
    cam = posts.cameras[0]
    f = wsoft.render(posts, ("hard", {"shadow_map_size": 256}), width=W, height=H)
    cov = f["A"] > 0
    pos = np.stack([f["P.X"][cov], f["P.Y"][cov], f["P.Z"][cov]], axis=1)
    gb = bake_gbuffer(pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1)), np.zeros(len(pos), np.int32), None, "cpu")
    p = CSM.make_params({**QUICK, "partition": "practical"})
    ctx = SimpleNamespace(camera=cam, origin=None, scene=posts)
    c0 = fit_cascades(ctx, sun, gb, p, {})
    moved = Camera(cam.path, cam.to_world.copy(), cam.orthographic, cam.tan_half, cam.offset, cam.clip)
    moved.to_world[:3, 3] += 0.3 * float(c0.texels[-1]) * cam.to_world[:3, 0]
    c1 = fit_cascades(SimpleNamespace(camera=moved, origin=None, scene=posts), sun, gb, p, {})
    for v0, v1 in zip(c0.views, c1.views):
        if v0 is None:
            continue
        t0 = (v0.window[1] - v0.window[0]) / v0.width
        assert (v1.window[1] - v1.window[0]) / v1.width == pytest.approx(t0, rel=1e-12)
        for ax in (0, 1):
            e0 = float(v0.origin @ v0.axes[:, ax] + v0.window[2 * ax])
            e1 = float(v1.origin @ v1.axes[:, ax] + v1.window[2 * ax])
            steps = (e1 - e0) / t0
            assert abs(steps - round(steps)) < 1e-6


# --------------------------------------------------------------------------- blend band


def _split_band(depth: np.ndarray, splits, cov: np.ndarray, width: int = 8) -> np.ndarray:
    """Pixels within ``width`` pixels (a 16-pixel band) of a split's iso-depth line."""
    idx = np.searchsorted(np.asarray(splits)[1:-1], depth)
    edge = np.zeros_like(cov)
    edge[:, 1:] |= (idx[:, 1:] != idx[:, :-1]) & cov[:, 1:] & cov[:, :-1]
    edge[1:, :] |= (idx[1:, :] != idx[:-1, :]) & cov[1:, :] & cov[:-1, :]
    band = edge.copy()
    for _ in range(width):
        grown = band.copy()
        grown[1:, :] |= band[:-1, :]
        grown[:-1, :] |= band[1:, :]
        grown[:, 1:] |= band[:, :-1]
        grown[:, :-1] |= band[:, 1:]
        band = grown
    return band & cov


@wp.kernel
def weights_at(splits: wp.array[float], band: wp.array[float], n: int, depths: wp.array[float],
               # outputs
               w: wp.array2d[float]):
    i = wp.tid()
    for k in range(n):
        w[i, k] = cascade_weight(splits, band, n, k, depths[i])


def test_cascade_weights_sum_to_one_and_blend_continuously():
    """Across every split the cascades' weights sum to 1, change by at most one step's share of the
    band between neighbouring depths (no jump), and are 1 away from the bands."""
    s = np.array([1.0, 3.0, 7.0, 15.0, 31.0])
    band = blend_band(s, 0.2)
    d = np.linspace(0.5, 35.0, 20001)
    w = wp.empty((len(d), 4), dtype=float, device="cpu")
    wp.launch(weights_at, dim=len(d), inputs=[wp.array(s, dtype=float), wp.array(band, dtype=float), 4, wp.array(d, dtype=float)],
              outputs=[w], device="cpu")
    w = w.numpy()
    assert np.allclose(w.sum(axis=1), 1.0, atol=1e-5)
    step = d[1] - d[0]
    assert np.abs(np.diff(w, axis=0)).max() <= step / band[:-1].min() * 1.01
    mid = (d > 3.0) & (d < 7.0 - band[1])
    assert np.all(w[mid, 1] == 1.0)
    inside = (d > 7.0 - band[1]) & (d < 7.0)
    assert inside.any() and np.all((w[inside, 1] > 0) & (w[inside, 2] > 0))  # the band blends both


def test_the_blend_band_keeps_the_error_near_splits(posts):
    """Against the reference (64 samples): the MAE in a 16-pixel band around each split is at most
    1.5 times the MAE away from the splits."""
    fs = wsoft.render(posts, [("csm", {**QUICK, "partition": "practical"}), ("reference", {"samples": 64})], width=W, height=H,
                      light="Sun")
    f, ref = fs["csm"], fs["reference"]
    cov = f["A"] > 0
    c = f.stats["counters"]["techniques"]["csm"]["Sun"]
    eye, fwd = camera_frame(posts.cameras[0])
    pos = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], axis=-1)
    depth = (pos - eye) @ fwd
    band = _split_band(depth, c["splits"], cov)
    err = np.abs(f.V - ref.V)
    away = cov & ~band
    assert band.sum() > 200 and away.sum() > 200
    assert err[band].mean() <= 1.5 * err[away].mean() + 1e-4, (err[band].mean(), err[away].mean())


# --------------------------------------------------------------------------- parameters and lights


@pytest.mark.parametrize("bad", [{"cascades": 0}, {"cascades": 9}, {"split_lambda": 1.5}, {"partition": "uniform"}, {"filter": "vsm"},
                                 {"blend": -0.1}, {"map_size": 128}, {"taps": 10, "filter": "pcf"}, {"filter_samples": 20},
                                 {"min_radius": 8.0, "max_radius": 4.0}, {"split_lambda": float("nan")}, {"splits": 3}])
def test_bad_parameters_are_refused(bad):
    with pytest.raises(ParameterError):
        get_technique("csm").make_params(bad)


def test_declines_local_lights():
    scene = posts_stage(rect=True)
    tech = CSM(CSM.make_params({}))
    rect = next(l for l in scene.lights if l.path.endswith("Rect"))
    sun = next(l for l in scene.lights if l.path.endswith("Sun"))
    why = tech.supports(scene, rect)
    assert why and "distant" in why and "\n" not in why
    assert tech.supports(scene, sun) is None
    assert tech.bake_support()


def test_casters_left_out_of_the_shadow_link_cast_no_shadow():
    """Every post excluded from the sun's shadowLink: the cascades hold only the ground, so V = 1 on
    the ground and the posts' tops, where the linked stage has the posts' shadows (the posts' sides
    are left out: at their foot the ground in the map darkens a sun-facing side's filter, as
    ``pcss``'s)."""
    posts = [f"/World/Post_{i}_{j}" for i in range(9) for j in range(9)]
    linked = wsoft.render(posts_stage(), ("csm", QUICK), width=W // 2, height=H // 2, light="Sun")
    free = wsoft.render(posts_stage(unlinked=tuple(posts)), ("csm", QUICK), width=W // 2, height=H // 2, light="Sun")
    lit_side = (free["A"] > 0) & (free["N.Z"] > 0.9)
    assert (linked.V[lit_side] < 0.5).sum() > 20
    assert np.all(free.V[lit_side] == 1.0)


# --------------------------------------------------------------------------- city


@pytest.mark.slow
def test_city_sun_beats_a_single_pcf_map_of_the_same_size():
    scene = wsoft.load_scene("city")
    res = wsoft.compare(scene, [("csm", {"map_size": 1024}), ("pcf", {"shadow_map_size": 1024})], samples=64, width=W, height=H,
                        light="Sun")
    a, b = res["csm"].stats["error"], res["pcf"].stats["error"]
    assert b["penumbra_pixels"] > 50
    assert a["mae_penumbra"] < b["mae_penumbra"], (a, b)
