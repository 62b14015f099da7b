"""UsdLux semantics that change who casts a light's shadow, on stages built in
memory: ``collection:shadowLink`` (excluded prims cast no shadow of that light, for every
technique, and are left out of its depth maps), ``inputs:shadow:distance`` (honoured or refused
with a one-line reason, per technique), ``inputs:shadow:color`` (tints ``R G B``, never ``V``),
what ``wsoft plan`` lists, and the reference against a brute-force count of the same rays."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import DISTANT_ONLY, SKY_ONLY, add_camera, add_quad, add_rect_light, make_stage, wsoft_cli, skip_if_no_local_lights

import wsoft
from wsoft.techniques import TECHNIQUES, create

NAMES = sorted(TECHNIQUES)
W, H = 64, 48
OCC_HALF = 0.4  # the blockers' half side
LIGHT = 0.4  # the rect light's side


def params_of(name: str) -> dict:
    """A technique's quick settings; the reference with 64 regular samples."""
    if name == "reference":
        return {"samples": 64, "jitter": False}
    return TECHNIQUES[name].quick_params


def two_blockers(heights=(1.0, 1.0), light_z: float = 3.0, lights=("/World/Light",), light_size: float = LIGHT):
    """A ground, blocker A at x = -1.2 and blocker B at x = +1.2 (heights ``heights``), square rect
    lights of side ``light_size`` above the origin, a camera that sees the ground under both."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_quad(st, "/World/A", (-1.2, 0, heights[0]), OCC_HALF)
    add_quad(st, "/World/B", (1.2, 0, heights[1]), OCC_HALF)
    for path in lights:
        add_rect_light(st, path, (0, 0, light_z), light_size, light_size)
    add_camera(st, "/World/Cam", (0, -7, 6), (0, 0, 0), focal=18.0)
    return st


def link(st, light: str, *, exclude=(), include=(), include_root=None):
    """Author ``light``'s ``collection:shadowLink``."""
    from pxr import Sdf, UsdLux

    col = UsdLux.LightAPI(st.GetPrimAtPath(light)).GetShadowLinkCollectionAPI()
    for p in exclude:
        col.GetExcludesRel().AddTarget(Sdf.Path(p))
    for p in include:
        col.GetIncludesRel().AddTarget(Sdf.Path(p))
    if include_root is not None:
        col.GetIncludeRootAttr().Set(include_root)


def set_distance(st, light: str, d: float):
    from pxr import UsdLux

    UsdLux.ShadowAPI.Apply(st.GetPrimAtPath(light)).CreateShadowDistanceAttr(d)


def umbra(f, x_center: float, half: float = 0.25):
    """Ground pixels well inside the umbra centred at (x_center, 0) (at least 4 of them)."""
    sel = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3) & (np.abs(f["P.X"] - x_center) < half) & (np.abs(f["P.Y"]) < half)
    assert sel.sum() >= 4, f"only {sel.sum()} pixels in the umbra at x = {x_center}"
    return sel


# umbra centres on the ground of blockers at x = -1.2 / +1.2 and height h under a light at height z
def shadow_x(x: float, h: float, z: float) -> float:
    return x * z / (z - h)


def render(scene, name, **kw):
    return wsoft.render(scene, name, width=W, height=H, device="cpu", **params_of(name), **kw)


# ------------------------------------------------------------------------------- loader


def test_loader_reads_the_shadow_controls():
    """Membership as Usd.CollectionAPI computes it: the default (an unauthored collection,
    includeRoot = true) includes everything; excludes; includeRoot = false with includes; the
    distance, colour and falloff attributes; only falloff (not applied) is still a warning."""
    st = two_blockers()
    s = wsoft.load_scene(st)
    (light,) = s.lights
    assert light.shadow_excluded == () and s.casting_mask(light) is None and light.shadow_distance == -1.0
    assert light.shadow_color == (0.0, 0.0, 0.0) and not [w for w in s.warnings if "shadow" in w]
    link(st, "/World/Light", exclude=["/World/A"])
    s = wsoft.load_scene(st)
    assert [s.prims[i] for i in s.lights[0].shadow_excluded] == ["/World/A"]
    m = s.casting_mask(s.lights[0])
    assert m.sum() == s.triangle_count - 2 and not m[s.tri_prim == s.prims.index("/World/A")].any()
    assert not [w for w in s.warnings if "shadowLink" in w or "shadow:distance" in w]  # applied: no warning
    st = two_blockers()
    link(st, "/World/Light", include=["/World/B"], include_root=False)
    s = wsoft.load_scene(st)
    assert sorted(s.prims[i] for i in s.lights[0].shadow_excluded) == ["/World/A", "/World/Ground"]
    from pxr import UsdLux

    sh = UsdLux.ShadowAPI.Apply(st.GetPrimAtPath("/World/Light"))
    sh.CreateShadowDistanceAttr(2.5)
    sh.CreateShadowColorAttr((0.25, 0.5, 1.0))
    sh.CreateShadowFalloffAttr(0.5)
    sh.CreateShadowFalloffGammaAttr(2.0)
    s = wsoft.load_scene(st)
    li = s.lights[0]
    assert (li.shadow_distance, li.shadow_color, li.shadow_falloff, li.shadow_falloff_gamma) == (2.5, (0.25, 0.5, 1.0), 0.5, 2.0)
    w = [x for x in s.warnings if "/World/Light" in x]
    assert len(w) == 1 and "inputs:shadow:falloff = 0.5" in w[0] and "not applied" in w[0]
    sh.CreateShadowDistanceAttr(-1.0)
    assert wsoft.load_scene(st).lights[0].distance_limited is False


def test_loader_instanced_casters_need_instancer_and_prototype():
    """A mesh a PointInstancer places casts when both the instancer and the prototype mesh are in
    the collection: excluding either leaves its instances out."""
    from pxr import Sdf, UsdGeom

    st = two_blockers()
    pi = UsdGeom.PointInstancer.Define(st, "/World/Trees")
    add_quad(st, "/World/Trees/Protos/Leaf", (0, 0, 0), 0.2)
    pi.CreatePrototypesRel().AddTarget(Sdf.Path("/World/Trees/Protos/Leaf"))
    pi.CreateProtoIndicesAttr([0, 0])
    pi.CreatePositionsAttr([(2.5, 2.0, 0.5), (-2.5, 2.0, 0.5)])
    from pxr import UsdLux

    excludes = UsdLux.LightAPI(st.GetPrimAtPath("/World/Light")).GetShadowLinkCollectionAPI().GetExcludesRel()
    for excluded in ("/World/Trees", "/World/Trees/Protos/Leaf"):  # one exclusion at a time
        excludes.ClearTargets(True)
        link(st, "/World/Light", exclude=[excluded])
        s = wsoft.load_scene(st)
        out = [s.prims[i] for i in s.lights[0].shadow_excluded]
        assert len(out) == 2 and all("@/World/Trees[" in p for p in out), (excluded, out)
    excludes.ClearTargets(True)
    assert wsoft.load_scene(st).lights[0].shadow_excluded == ()


def test_loader_double_sided_and_animated_visibility():
    """The authored ``doubleSided`` (UsdGeom's uniform attribute) is kept per triangle (eye-view
    culling: a single-sided quad seen from behind is not seen; a ``primvars:doubleSided`` is no
    UsdGeom property: a warning, not read), and a time-sampled ``visibility`` is read at the load
    time code."""
    from pxr import UsdGeom

    st = make_stage()
    add_quad(st, "/World/Two", (0, 0, 0), 1, double_sided=True)
    add_quad(st, "/World/One", (3, 0, 0), 1, double_sided=False)
    blink = add_quad(st, "/World/Blink", (-3, 0, 0), 1)
    vis = UsdGeom.Imageable(blink).CreateVisibilityAttr()
    vis.Set(UsdGeom.Tokens.inherited, 0)
    vis.Set(UsdGeom.Tokens.invisible, 10)
    add_rect_light(st, "/World/L", (0, 0, 3), 1, 1)
    s = wsoft.load_scene(st, time=0)
    ds = {p: bool(s.tri_double_sided[s.tri_prim == i].all()) for i, p in enumerate(s.prims)}
    assert ds == {"/World/Two": True, "/World/One": False, "/World/Blink": True}
    assert not [w for w in s.warnings if "doubleSided" in w]
    from pxr import Sdf

    st.GetPrimAtPath("/World/One").CreateAttribute("primvars:doubleSided", Sdf.ValueTypeNames.Bool).Set(True)  # not UsdGeom's
    s2 = wsoft.load_scene(st, time=0)
    assert not s2.tri_double_sided[s2.tri_prim == s2.prims.index("/World/One")].any()
    assert any("/World/One" in w and "primvars:doubleSided is not a UsdGeom property" in w for w in s2.warnings)
    st.GetPrimAtPath("/World/One").RemoveProperty("primvars:doubleSided")
    assert "/World/Blink" not in wsoft.load_scene(st, time=10).prims
    assert "/World/Blink" in wsoft.load_scene(st, time=5).prims  # held (not interpolated) until 10
    # seen from below, the single-sided quad is culled (the camera sees nothing there), the double-sided one is not
    add_camera(st, "/World/Below", (1.5, 0, -6), (1.5, 0, 0), up=(0, 1, 0))
    f = wsoft.render(wsoft.load_scene(st, time=0), "hard", width=W, height=H, device="cpu", camera="/World/Below", shadow_map_size=256)
    seen_x = f["P.X"][f["A"] > 0]
    assert (np.abs(seen_x) < 0.9).sum() > 50 and (np.abs(seen_x - 3) < 0.9).sum() == 0


# ------------------------------------------------------------------------------- shadowLink, every technique


@pytest.mark.parametrize("name", NAMES)
def test_excluded_blocker_casts_no_shadow(name):
    """Blocker A left out of the light's shadowLink: no shadow under it (V ~ 1, it is still seen and
    still drawn in the G-buffer), blocker B still shadows; the depth maps hold only the casters."""
    skip_if_no_local_lights(name)
    st = two_blockers()
    link(st, "/World/Light", exclude=["/World/A"])
    scene = wsoft.load_scene(st)
    f = render(scene, name)
    xa, xb = shadow_x(-1.2, 1.0, 3.0), shadow_x(1.2, 1.0, 3.0)
    assert f.V[umbra(f, xa)].min() > 0.95, name
    assert f.V[umbra(f, xb)].mean() < 0.2, name
    assert (np.abs(f["P.Z"][f["A"] > 0] - 1.0) < 1e-3).sum() > 10  # the blockers are seen
    maps = {n: c["casting_triangles"] for n, c in f.stats["counters"]["passes"].items() if "casting_triangles" in c}
    assert all(v == scene.triangle_count - 2 for v in maps.values())
    if name not in ("reference", "salzman", "rtdenoise"):  # rtdenoise, as the reference, traces rays and draws no map
        assert maps, f"{name}: no depth map drew the light's casters only"


@pytest.mark.parametrize("name", NAMES)
def test_two_lights_blocker_linked_to_one(name):
    """Two lights over the same blockers; A is in L1's shadowLink only (L2 excludes it): A shadows
    L1's light and not L2's; B shadows both. Each light's maps are its own."""
    skip_if_no_local_lights(name)
    st = two_blockers(lights=("/World/L1", "/World/L2"))
    link(st, "/World/L2", exclude=["/World/A"])
    scene = wsoft.load_scene(st)
    f = render(scene, name)
    xa, xb = shadow_x(-1.2, 1.0, 3.0), shadow_x(1.2, 1.0, 3.0)
    assert f["V.L1"][umbra(f, xa)].mean() < 0.2 and f["V.L1"][umbra(f, xb)].mean() < 0.2, name
    assert f["V.L2"][umbra(f, xa)].min() > 0.95 and f["V.L2"][umbra(f, xb)].mean() < 0.2, name


@pytest.mark.parametrize("name", NAMES)
def test_include_root_false_with_explicit_includes(name):
    """includeRoot = false and includes = [B]: only B casts (the ground and A do not); the ground,
    excluded, still receives B's shadow."""
    skip_if_no_local_lights(name)
    st = two_blockers()
    link(st, "/World/Light", include=["/World/B"], include_root=False)
    scene = wsoft.load_scene(st)
    assert scene.casting_mask(scene.lights[0]).sum() == 2
    f = render(scene, name)
    assert f.V[umbra(f, shadow_x(-1.2, 1.0, 3.0))].min() > 0.95, name
    assert f.V[umbra(f, shadow_x(1.2, 1.0, 3.0))].mean() < 0.2, name


@pytest.mark.parametrize("name", [n for n in NAMES if not TECHNIQUES[n].distance_refusal and n not in SKY_ONLY])
def test_shadow_distance_under_a_distant_light(name):
    """The same near and far blockers under a sun straight down (an orthographic map: depth along
    the light): the near one shadows, the far one does not."""
    from pxr import UsdLux

    from wsoft.stages import add_sun

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_quad(st, "/World/A", (-1.2, 0, DIST_HEIGHTS[0]), OCC_HALF)
    add_quad(st, "/World/B", (1.2, 0, DIST_HEIGHTS[1]), OCC_HALF)
    sun = add_sun(st, "/World/Sun", 2.0, rotate=(0.0, 0.0, 0.0))
    UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowDistanceAttr(DISTANCE)
    add_camera(st, "/World/Cam", (0, -7, 6), (0, 0, 0))
    f = render(wsoft.load_scene(st), name)
    assert f.V[umbra(f, -1.2)].mean() < 0.2, name
    assert f.V[umbra(f, 1.2)].min() > 0.95, name


def test_no_link_adds_no_pass_and_no_triangle_list():
    """The common case (nothing excluded, no distance): no caster list (no counters of one), no
    warnings."""
    scene = wsoft.load_scene(two_blockers())
    f = render(scene, "pcss")
    assert not any("casting_triangles" in c for c in f.stats["counters"]["passes"].values())
    assert not [w for w in f.stats["warnings"] if "shadow" in w]


# ------------------------------------------------------------------------------- shadow:distance


DIST_HEIGHTS = (0.5, 2.0)  # A near the ground (within the distance), B far above it (beyond)
DIST_LIGHT_Z = 4.0
DISTANCE = 1.0


@pytest.mark.parametrize("name", NAMES)
def test_shadow_distance_honoured_or_refused(name):
    """shadow:distance = 1: blocker A, 0.5 above the ground, shadows; blocker B, 2 above it, does not
    (its occluder distance along every shadow ray exceeds 1). A technique that cannot honour it
    declines the light in one line naming shadow:distance, and render stops with that line."""
    skip_if_no_local_lights(name)
    st = two_blockers(DIST_HEIGHTS, DIST_LIGHT_Z)
    scene0 = wsoft.load_scene(st)
    set_distance(st, "/World/Light", DISTANCE)
    scene = wsoft.load_scene(st)
    tech = create(name, params_of(name))
    why = tech.supports(scene, scene.lights[0])
    xa, xb = shadow_x(-1.2, DIST_HEIGHTS[0], DIST_LIGHT_Z), shadow_x(1.2, DIST_HEIGHTS[1], DIST_LIGHT_Z)
    if why is not None:
        assert TECHNIQUES[name].distance_refusal and "inputs:shadow:distance = 1" in why and "\n" not in why
        assert tech.supports(scene0, scene0.lights[0]) is None  # only the distance is refused
        with pytest.raises(wsoft.ParameterError, match="shadow:distance"):
            render(scene, name)
        return
    assert not TECHNIQUES[name].distance_refusal
    f0, f = render(scene0, name), render(scene, name)
    assert f0.V[umbra(f0, xb)].mean() < 0.2, name  # without the distance B does shadow: the case is real
    assert f.V[umbra(f, xa)].mean() < 0.2, name
    assert f.V[umbra(f, xb)].min() > 0.95, name
    caveat = TECHNIQUES[name].distance_caveat  # the casters it tests (a depth map's nearest): said in a warning
    warned = [w for w in f.stats["warnings"] if "inputs:shadow:distance = 1 is tested against" in w]
    assert (warned and caveat in warned[0]) if caveat else not warned, (name, warned)
    if name in ("hard", "pcf", "pcss"):
        assert caveat == "the caster nearest the light in each texel of the depth map"


def test_distance_techniques():
    """Which techniques honour a finite shadow:distance: the ray-traced ones exactly, and the depth
    maps read tap by tap; the filtered ones refuse."""
    honour = {n for n, c in TECHNIQUES.items() if not c.distance_refusal}
    assert {"hard", "izb", "pcf", "pcss", "reference"} <= honour
    assert {n for n, c in TECHNIQUES.items() if not c.distance_refusal and not c.distance_caveat} >= {"izb", "reference"}


def test_hard_distance_known_limit_stacked_casters():
    """The depth map keeps the caster nearest the light: a blocker beyond the distance right above
    one within it hides it from hard (lit), where the reference (every caster) shadows. Pinned, and
    warned about in the frame's stats."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_quad(st, "/World/Low", (0, 0, 0.5), OCC_HALF)
    add_quad(st, "/World/High", (0, 0, 2.0), 0.8)
    add_rect_light(st, "/World/Light", (0, 0, 4), LIGHT, LIGHT)
    add_camera(st, "/World/Cam", (0, -7, 6), (0, 0, 0))
    set_distance(st, "/World/Light", DISTANCE)
    scene = wsoft.load_scene(st)
    ref, hard = render(scene, "reference"), render(scene, "hard")
    sel = umbra(ref, 0.0)
    assert ref.V[sel].mean() < 0.2 and hard.V[sel].min() > 0.95
    assert any("a caster behind it within the distance is missed" in w for w in hard.stats["warnings"])


# ------------------------------------------------------------------------------- the reference, brute force


def brute_force_visibility(f, light_pos, light_size, occluders, distance: float, samples: int = 64) -> np.ndarray:
    """Per pixel: the fraction of the regular pattern's light points (stratum centres of an m x m
    grid over the rect light) whose segment from the pixel's surface point is blocked by no
    casting square (``occluders``: (x, y, z, half)) within ``distance`` of it (-1: any)."""
    m = int(round(np.sqrt(samples)))
    u = (np.arange(m) + 0.5) / m * 2 - 1
    h = light_size / 2
    pts = np.array([[light_pos[0] + a * h, light_pos[1] + b * h, light_pos[2]] for b in u for a in u])
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], -1).astype(np.float64)
    vis = np.zeros(P.shape[:2])
    for q in pts:
        d = q - P
        length = np.linalg.norm(d, axis=-1)
        blocked = np.zeros(P.shape[:2], bool)
        for (ox, oy, oz, half) in occluders:
            t = (oz - P[..., 2]) / d[..., 2]
            x = P[..., 0] + t * d[..., 0]
            y = P[..., 1] + t * d[..., 1]
            hit = (t > 1e-6) & (t < 1) & (np.abs(x - ox) <= half) & (np.abs(y - oy) <= half)
            if distance >= 0:
                hit &= t * length <= distance
            blocked |= hit
        vis += ~blocked
    return vis / len(pts)


@pytest.mark.parametrize("traversal", ["ray", "packet"])
def test_reference_equals_brute_force(traversal):
    """The reference with a shadowLink (A excluded) and a shadow:distance (B beyond it, a third
    blocker C within it) against the same rays counted in numpy, on the ground."""
    st = two_blockers(DIST_HEIGHTS, DIST_LIGHT_Z, light_size=2.0)  # a wide light: wide penumbrae
    add_quad(st, "/World/C", (0.0, 0.9, 0.7), 0.4)
    link(st, "/World/Light", exclude=["/World/A"])
    set_distance(st, "/World/Light", DISTANCE)
    scene = wsoft.load_scene(st)
    f = wsoft.render(scene, "reference", width=W, height=H, device="cpu", samples=64, jitter=False, traversal=traversal)
    occ = [(1.2, 0.0, DIST_HEIGHTS[1], OCC_HALF), (0.0, 0.9, 0.7, 0.4)]  # B (beyond the distance) and C; A excluded
    expect = brute_force_visibility(f, (0, 0, DIST_LIGHT_Z), 2.0, occ, DISTANCE)
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    diff = np.abs(f.V - expect)[ground]
    assert (diff < 1e-6).mean() > 0.99 and diff.max() <= 1.5 / 64
    assert ((expect[ground] > 0) & (expect[ground] < 1)).sum() > 15  # penumbrae were compared
    none = brute_force_visibility(f, (0, 0, DIST_LIGHT_Z), 2.0, occ + [(-1.2, 0.0, DIST_HEIGHTS[0], OCC_HALF)], -1.0)
    assert np.abs(none - expect)[ground].max() > 0.5  # the link and the distance changed the answer


# ------------------------------------------------------------------------------- shadow colour, plan


def test_shadow_color_tints_rgb_not_v():
    """inputs:shadow:color = (1, 0, 0): in the umbra R rises (the shadow is red), G and B do not, V is
    the same; where lit nothing changes."""
    from pxr import UsdLux

    st = two_blockers()
    f0 = render(wsoft.load_scene(st), "hard")
    UsdLux.ShadowAPI.Apply(st.GetPrimAtPath("/World/Light")).CreateShadowColorAttr((1.0, 0.0, 0.0))
    f = render(wsoft.load_scene(st), "hard")
    assert np.array_equal(f.V, f0.V)
    sel = umbra(f, shadow_x(1.2, 1.0, 3.0))
    assert (f["R"][sel] > f0["R"][sel] + 0.1).all()
    assert np.array_equal(f["G"], f0["G"]) and np.array_equal(f["B"], f0["B"])
    lit = (f.V == 1) & (f["A"] > 0)
    assert lit.sum() > 100 and np.array_equal(f["R"][lit], f0["R"][lit])


def test_plan_lists_the_shadow_controls(tmp_path):
    """wsoft plan (text and --json): per light the shadowLink summary, the distance and who honours
    it, the colour (applied to R G B, not to V) and the falloff (not applied); techniques refusing the
    distance are listed as not applicable with the reason."""
    from pxr import UsdLux

    st = two_blockers()
    link(st, "/World/Light", exclude=["/World/A"])
    sh = UsdLux.ShadowAPI.Apply(st.GetPrimAtPath("/World/Light"))
    sh.CreateShadowDistanceAttr(2.5)
    sh.CreateShadowColorAttr((0.5, 0.0, 0.0))
    sh.CreateShadowFalloffAttr(0.5)
    path = tmp_path / "linked.usda"
    st.GetRootLayer().Export(str(path))
    run = lambda *a: wsoft_cli("plan", str(path), *a)  # noqa: E731
    p = run("--json")
    assert p.returncode == 0, p.stderr
    plan = json.loads(p.stdout)
    sh = plan["lights"][0]["shadow"]
    assert sh["link"]["excluded_prims"] == 1 and sh["link"]["prims"] == 3 and sh["link"]["excluded"] == ["/World/A"]
    from wsoft.techniques import TECHNIQUES

    refused = ", ".join(sorted(t for t, c in TECHNIQUES.items() if c.distance_refusal and t not in DISTANT_ONLY | SKY_ONLY))
    assert sh["distance"] == 2.5 and f"refused by {refused}" in sh["distance_applied"] and refused.startswith("dcs, esm, essm")
    assert sh["color"] == [0.5, 0.0, 0.0] and sh["color_applied"] == "applied to R G B, not to V"
    assert sh["falloff"] == 0.5 and sh["falloff_applied"].startswith("not applied")
    only_other_lights = DISTANT_ONLY | SKY_ONLY  # they decline the rect light itself
    assert only_other_lights <= set(plan["not_applicable"])
    by_distance = {t: ws for t, ws in plan["not_applicable"].items() if t not in only_other_lights}
    assert set(by_distance) == {t for t, c in TECHNIQUES.items() if c.distance_refusal} - only_other_lights >= {"dcs", "esm", "pwedge", "vsm"}
    assert all("inputs:shadow:distance = 2.5" in w["reason"] for ws in by_distance.values() for w in ws)
    t = run()
    assert t.returncode == 0, t.stderr
    assert "collection:shadowLink: 1 of 3 prims excluded (/World/A)" in t.stdout
    assert "shadow:distance: 2.5 scene units: honoured by hard, izb, pcf, pcss, reference" in t.stdout
    assert "shadow:color: (0.5, 0, 0): applied to R G B, not to V" in t.stdout
    assert "shadow:falloff: 0.5, falloffGamma 1: not applied" in t.stdout
    assert "vsm: not applicable to /World/Light: inputs:shadow:distance = 2.5 cannot be honoured" in t.stdout


def test_hard_read_texels_map_passes_through_excluded_prims():
    """hard's map of the texels receivers read (one ray each) holds the light's casters only, as its
    rasterized map does: A left out casts nothing, B still shadows, and the two maps agree."""
    st = two_blockers()
    link(st, "/World/Light", exclude=["/World/A"])
    scene = wsoft.load_scene(st)
    read, full = render(scene, "hard", map_texels="read"), render(scene, "hard", map_texels="all")
    assert read.V[umbra(read, shadow_x(-1.2, 1.0, 3.0))].min() > 0.95
    assert read.V[umbra(read, shadow_x(1.2, 1.0, 3.0))].mean() < 0.2
    cov = full["A"] > 0
    assert np.mean(read.V[cov] != full.V[cov]) < 0.002
