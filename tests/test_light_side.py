"""Which side of a light emits, and what shape it has.

A rect or disk light emits from its front only, along its transformed local −Z axis (a rotation
or a negative scale can turn it away from its receivers): every technique gives V = 0 behind its
plane, a frame says how many receivers lie there and ``wsoft plan`` lists where it emits. A
non-uniformly scaled disk light is an ellipse and a sphere light an ellipsoid: the reference
samples them exactly (checked against a brute-force numpy integration), the techniques that size
their penumbrae by the light follow the ellipse's two axes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage, wsoft_cli, skip_if_no_local_lights

import wsoft
from wsoft.scene.types import LIGHT_DISK, LIGHT_SPHERE
from wsoft.techniques import TECHNIQUES

W, H = 48, 36
FLIPS = {"rotate_x_180": ("rotate", (180, 0, 0)), "scale_1_1_-1": ("scale", (1, 1, -1)), "scale_-1_-1_-1": ("scale", (-1, -1, -1))}


def quick(name: str, **extra) -> dict:
    """A technique's quick parameters with 256-texel maps (64 samples for the reference)."""
    cls = TECHNIQUES[name]
    p = dict(cls.quick_params)
    if cls.size_param:
        p[cls.size_param] = 256
    if name == "reference":
        p["samples"] = 64
    p.update(extra)
    return p


def _xform(prim, op: str, value):
    from pxr import Gf, UsdGeom

    xf = UsdGeom.XformCommonAPI(prim)
    if op == "rotate":
        xf.SetRotate(Gf.Vec3f(*value))
    else:
        xf.SetScale(Gf.Vec3f(*value))


def _base(flip: str | None = None):
    """The adversarial corpus's base (ground at z = 0, a 2 x 2 occluder at z = 1, a 1 x 1 rect
    light at z = 3), the light turned by ``flip``."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_quad(st, "/World/Occluder", (0, 0, 1), 1)
    light = add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    if flip is not None:
        _xform(light.GetPrim(), *FLIPS[flip])
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return st


# --------------------------------------------------------------------------- the emitting side


@pytest.mark.parametrize("flip", FLIPS)
def test_a_turned_light_emits_along_its_transformed_minus_z(flip):
    light = wsoft.load_scene(_base(flip)).lights[0]
    assert np.allclose(light.direction, (0, 0, 1), atol=1e-6), light.direction
    assert light.one_sided


def test_a_mirror_that_keeps_minus_z_keeps_the_light_facing_down():
    st = _base()
    _xform(st.GetPrimAtPath("/World/Light"), "scale", (-1, 1, 1))
    light = wsoft.load_scene(st).lights[0]
    assert np.allclose(light.direction, (0, 0, -1), atol=1e-6) and np.linalg.det(light.frame) < 0


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_a_light_facing_away_gives_no_light_and_says_so(device, technique):
    """The base's light turned 180 degrees about X: every receiver lies behind it (V = 0), a warning
    names the light and the count, and the light view does not claim those receivers as mapped."""
    skip_if_no_local_lights(technique)
    scene = wsoft.load_scene(_base("rotate_x_180"))
    f = wsoft.render(scene, technique, width=W, height=H, device=device, **quick(technique))
    cov = f["A"] > 0
    assert cov.sum() > 500
    assert f.V[cov].max() == 0.0, (technique, float(f.V[cov].mean()))
    behind = [w for w in f.stats["warnings"] if "/World/Light" in w and "behind its emitting plane" in w]
    assert len(behind) == 1 and f"{int(cov.sum())} of {int(cov.sum())} visible samples" in behind[0], f.stats["warnings"]
    assert not any("single-frustum" in w for w in f.stats["warnings"]), f.stats["warnings"]
    passes = f.stats["counters"]["passes"]
    assert passes["light_behind[Light]"]["receivers_behind_light"] == int(cov.sum())
    for name, c in passes.items():
        if name.startswith("fit_light_view"):
            assert c["receivers_outside"] == 0 and c["receivers_behind_light"] == int(cov.sum()), (name, c)


def _tilted_light():
    """A bare ground under a 2 x 2 rect light at (0, 1, 2) turned 45 degrees about X, facing +y and
    down: its plane meets the ground at y = -1; the ground beyond is lit (the whole light is above
    it), the ground before it lies behind the light."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    light = add_rect_light(st, "/World/Light", (0, 1, 2), 2, 2)
    _xform(light.GetPrim(), "rotate", (45, 0, 0))
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return wsoft.load_scene(st)


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_receivers_behind_a_light_get_none_of_it_those_in_front_are_lit(device, technique):
    skip_if_no_local_lights(technique)
    scene = _tilted_light()
    assert np.allclose(scene.lights[0].direction, (0, 0.5**0.5, -0.5**0.5), atol=1e-6)
    f = wsoft.render(scene, technique, width=W, height=H, device=device, **quick(technique))
    cov = f["A"] > 0
    y = f["P.Y"]
    behind, front = cov & (y < -1.05), cov & (y > 0.0)  # (nearer the plane a map sees the ground edge-on)
    assert behind.sum() > 200 and front.sum() > 300
    assert f.V[behind].max() == 0.0, (technique, float(f.V[behind].mean()))
    # lit (1 for most; a bare ground seen at 45 degrees self-shadows under vssm's and salzman's filtering: 0.70, 0.95)
    assert f.V[front].mean() > 0.6, (technique, float(f.V[front].mean()))
    n = f.stats["counters"]["passes"]["light_behind[Light]"]["receivers_behind_light"]
    assert behind.sum() <= n <= (cov & (y < -0.95)).sum()


def test_a_light_facing_its_receivers_adds_no_pass():
    """No point of the scene lies behind the base's light: no light_behind pass, no counter."""
    f = wsoft.render(wsoft.load_scene(_base()), "reference", width=W, height=H, device="cpu", samples=4)
    assert "light_behind[Light]" not in f.stats["passes"]
    assert not any("behind its emitting plane" in w for w in f.stats["warnings"])


@pytest.mark.parametrize("technique", sorted(n for n, c in TECHNIQUES.items() if c(c.make_params(quick(n))).bake_support() is None))
def test_a_bake_of_a_light_facing_away_writes_zero(device, technique):
    skip_if_no_local_lights(technique)
    stage = _base("scale_1_1_-1")
    stats = {}
    layer = wsoft.bake(stage, technique, device=device, stats=stats, **quick(technique))
    values = []
    for path in ("/World/Ground", "/World/Occluder"):
        spec = layer.GetPrimAtPath(path)
        assert spec is not None, path
        values.append(np.asarray(spec.attributes["primvars:wsoft:visibility:Light"].default, np.float32))
    v = np.concatenate(values)
    assert v.size >= 8 and v.max() == 0.0, (technique, v)
    assert any("behind its emitting plane" in w and "bake points" in w for w in stats["warnings"]), stats["warnings"]


def test_plan_says_where_a_light_emits_and_what_lies_behind_it(tmp_path):
    path = str(tmp_path / "away.usda")
    stage = _base("rotate_x_180")
    stage.GetRootLayer().Export(path)
    r = wsoft_cli("plan", path, "--json", "-t", "hard")
    assert r.returncode == 0, r.stderr
    (light,) = json.loads(r.stdout)["lights"]
    assert light["emits"]["side"] == "front" and np.allclose(light["emits"]["direction"], (0, 0, 1), atol=1e-6)
    assert light["emits"]["points_behind"] == 8 and light["emits"]["points"] == 8
    r = wsoft_cli("plan", path, "-t", "hard")
    assert r.returncode == 0, r.stderr
    line = next(ln for ln in r.stdout.splitlines() if "emits:" in ln)
    assert "8 of 8 mesh points lie behind" in line, line
    base = str(tmp_path / "base.usda")
    stage = _base()
    stage.GetRootLayer().Export(base)
    (light,) = json.loads(wsoft_cli("plan", base, "--json", "-t", "hard").stdout)["lights"]
    assert light["emits"]["points_behind"] == 0


# --------------------------------------------------------------------------- the light's shape


def _disk_stage(kind: str = "disk", scale=(4.0, 0.25, 1.0), radius: float = 0.5):
    """Ground, the base's 2 x 2 occluder at z = 1 and a disk (or sphere) light of ``radius`` at
    z = 3 scaled by ``scale``."""
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_quad(st, "/World/Occluder", (0, 0, 1), 1)
    light = (UsdLux.DiskLight if kind == "disk" else UsdLux.SphereLight).Define(st, "/World/Light")
    light.CreateRadiusAttr(radius)
    xf = UsdGeom.XformCommonAPI(light)
    xf.SetTranslate(Gf.Vec3d(0, 0, 3))
    xf.SetScale(Gf.Vec3f(*scale))
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return wsoft.load_scene(st)


def test_a_non_uniform_scale_makes_an_ellipse_and_an_ellipsoid():
    disk = _disk_stage().lights[0]
    assert disk.kind == LIGHT_DISK and disk.elliptical
    assert np.allclose(disk.semi_axes, (2.0, 0.125)) and disk.radius == pytest.approx(2.0)
    assert "2 x 0.125" in disk.size_description()
    sphere = _disk_stage("sphere").lights[0]
    assert sphere.kind == LIGHT_SPHERE and sphere.elliptical
    assert sorted(sphere.semi_axes) == pytest.approx([0.125, 0.5, 2.0]) and sphere.radius == pytest.approx(2.0)
    # along the frame's axes: the long one along world x
    axes = sphere.frame * np.asarray(sphere.semi_axes)[None, :]
    assert np.abs(axes[0]).max() == pytest.approx(2.0)
    for kind in ("disk", "sphere"):
        round_ = _disk_stage(kind, scale=(2.0, 2.0, 2.0)).lights[0]
        assert not round_.elliptical and round_.radius == 1.0


def _ellipse_points(n: int = 160) -> np.ndarray:
    """Points of the unit disk on an n x n grid (uniform in area)."""
    g = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(g, g)
    keep = x * x + y * y <= 1
    return np.stack([x[keep], y[keep]], 1)


def _brute_disk(p: np.ndarray, a: float, b: float) -> np.ndarray:
    """V at the points ``p`` of a horizontal elliptical light (semi-axes a along x, b along y) at
    z = 3 over the 2 x 2 occluder at z = 1, by brute force over the light's area."""
    u = _ellipse_points()
    q = np.stack([u[:, 0] * a, u[:, 1] * b, np.full(len(u), 3.0)], 1)
    return _blocked_fraction(p, q)


def _blocked_fraction(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """1 - the fraction of segments p -> q (every q for each p) crossing the occluder |x|, |y| <= 1 at z = 1."""
    out = np.empty(len(p))
    for i in range(0, len(p), 64):
        pp = p[i:i + 64, None, :]
        t = (1.0 - pp[..., 2]) / (q[None, :, 2] - pp[..., 2])
        x = pp[..., 0] + t * (q[None, :, 0] - pp[..., 0])
        y = pp[..., 1] + t * (q[None, :, 1] - pp[..., 1])
        hit = (t > 1e-6) & (t < 1.0) & (np.abs(x) <= 1.0) & (np.abs(y) <= 1.0)
        out[i:i + 64] = 1.0 - hit.mean(axis=1)
    return out


def _ground(f):
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    return g, np.stack([f["P.X"][g], f["P.Y"][g], f["P.Z"][g]], 1).astype(np.float64)


def test_the_reference_samples_an_elliptical_disk_exactly(device):
    """A DiskLight of radius 0.5 scaled 4 x 0.25: an ellipse of semi-axes 2 (x) and 0.125 (y). Its
    shadow of the 2 x 2 occluder has a penumbra 2 wide across x and 0.125 across y; the reference
    matches the brute-force integral over the ellipse, not the one over a circle of the mean radius."""
    f = wsoft.render(_disk_stage(), "reference", width=W, height=H, device=device, samples=64)
    g, p = _ground(f)
    ellipse, circle = _brute_disk(p, 2.0, 0.125), _brute_disk(p, 1.0625, 1.0625)
    pen = ((ellipse > 0.01) & (ellipse < 0.99)) | ((circle > 0.01) & (circle < 0.99))
    assert pen.sum() > 200 and np.abs(ellipse - circle)[pen].mean() > 0.1  # the two answers are far apart there
    err = np.abs(f.V[g] - ellipse)
    assert err[pen].mean() < 0.02 and err.max() < 0.1, (err[pen].mean(), err.max())  # 64 stratified samples
    # the penumbra's widths: across x (near y = 0) from |x| = 0.5 to 2.5, across y (near x = 0) within 1.4375 < |y| < 1.5625
    v = f.V[g]
    soft = (v > 0.02) & (v < 0.98)
    across_x = np.abs(p[soft & (np.abs(p[:, 1]) < 0.5), 0])
    across_y = np.abs(p[soft & (np.abs(p[:, 0]) < 0.5), 1])
    assert across_x.min() < 0.8 and across_x.max() > 2.2, (across_x.min(), across_x.max())
    assert across_y.size == 0 or (across_y.min() > 1.3 and across_y.max() < 1.7), across_y


def _sizes_by_light(technique: str) -> bool:
    """Does the technique's shadow change with the light's size (a round disk of radius 0.25 and 1)?"""
    a = wsoft.render(_disk_stage(scale=(0.5, 0.5, 1)), technique, width=W, height=H, device="cpu", **quick(technique)).V
    b = wsoft.render(_disk_stage(scale=(2, 2, 1)), technique, width=W, height=H, device="cpu", **quick(technique)).V
    return float(np.abs(a - b).mean()) > 0.01  # the reference: 0.019; fixed-size kernels that only refit their view: <= 0.0025


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_every_technique_that_sizes_its_shadow_by_the_light_follows_the_ellipse(technique):
    """Closer to the ellipse's brute-force answer than to that of a circle of the mean radius (the
    techniques whose shadow does not depend on the light's size, hard shadows and fixed-size kernels,
    are skipped)."""
    skip_if_no_local_lights(technique)
    if not _sizes_by_light(technique):
        pytest.skip(f"{technique}'s shadow does not depend on the light's size")
    # a stochastic technique at its most rays: at 2 its noise (0.03 mean) hides the ellipse's difference from the circle
    more = {"samples": 8} if technique == "rtdenoise" else {}
    f = wsoft.render(_disk_stage(), technique, width=W, height=H, device="cpu", **(quick(technique) | more))
    g, p = _ground(f)
    e_ellipse = np.abs(f.V[g] - _brute_disk(p, 2.0, 0.125)).mean()
    e_circle = np.abs(f.V[g] - _brute_disk(p, 1.0625, 1.0625)).mean()
    assert e_ellipse < 0.75 * e_circle, (technique, e_ellipse, e_circle)
    assert not any("ellipsoid" in w for w in f.stats["warnings"])


def _brute_ellipsoid(p: np.ndarray, s: np.ndarray, c: np.ndarray) -> np.ndarray:
    """V at ``p`` of an axis-aligned ellipsoidal sphere light (semi-axes ``s``, centre ``c``) over
    the occluder: the fraction of its silhouette (the section of the ellipsoid by the polar plane of
    each point, where the tangent cone touches it) whose segments to the point are unblocked,
    sampled on a grid of that plane."""
    out = np.empty(len(p))
    for i, pi in enumerate(p):
        k = (pi - c) / s**2  # the polar plane: k . (x - c) = 1
        n = k / np.linalg.norm(k)
        x0 = c + k / np.dot(k, k)  # the plane's point nearest the centre
        t1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        g = np.linspace(-2.2, 2.2, 601)
        a, b = np.meshgrid(g, g)
        q = x0 + a.reshape(-1, 1) * t1 + b.reshape(-1, 1) * t2
        q = q[(((q - c) / s) ** 2).sum(1) <= 1.0]
        out[i] = _blocked_fraction(pi[None], q)[0]
    return out


def test_the_reference_samples_an_ellipsoids_silhouette(device):
    """A SphereLight of radius 0.5 scaled 4 x 0.25 x 1: the reference sees the silhouette ellipse
    the point sees (checked on 40 ground points against a brute-force integral over that section
    of the ellipsoid); the techniques that size a filter kernel by the light use its bounding
    sphere and say so."""
    scene = _disk_stage("sphere")
    f = wsoft.render(scene, "reference", width=W, height=H, device=device, samples=64)
    g, p = _ground(f)
    near = np.flatnonzero(np.abs(_brute_disk(p, 2.0, 0.5) - 0.5) < 0.49)  # around the penumbra
    pick = np.random.default_rng(1).choice(near, 40, replace=False)
    truth = _brute_ellipsoid(p[pick], np.array([2.0, 0.125, 0.5]), np.array([0.0, 0.0, 3.0]))
    ball = _brute_ellipsoid(p[pick], np.full(3, 0.5 * (4 + 0.25 + 1) / 3), np.array([0.0, 0.0, 3.0]))  # a ball of the mean radius
    assert np.abs(truth - ball).mean() > 0.1
    err = np.abs(f.V[g][pick] - truth)
    assert err.mean() < 0.02 and err.max() < 0.08, (err.mean(), err.max())  # 64 stratified samples
    assert not any("ellipsoid" in w for w in f.stats["warnings"])


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_an_ellipsoid_is_sampled_or_its_approximation_named(technique):
    skip_if_no_local_lights(technique)
    cls = TECHNIQUES[technique]
    f = wsoft.render(_disk_stage("sphere"), technique, width=W, height=H, device="cpu", **quick(technique))
    said = [w for w in f.stats["warnings"] if "ellipsoid" in w and "/World/Light" in w]
    assert len(said) == (1 if cls.ellipsoid_caveat else 0), f.stats["warnings"]
    if said:
        assert "bounding sphere" in said[0] and "radius 2" in said[0]
    assert np.isfinite(f.V).all()
