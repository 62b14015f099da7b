"""The irregular z-buffer scenes (``tower``, ``tunnel_fan``; ``wsoft.stages.scenes``): a point light,
thin occluders, and hard shadows that a render actually shows on the receivers."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path

import wsoft
from wsoft.scene.types import LIGHT_POINT

# scene -> (file, min triangles, max triangles)
IZB = {
    "tower": ("tower.usda", 3_000, 20_000),
    "tunnel_fan": ("tunnel_fan.usda", 1_000, 20_000),
}

_CACHE: dict = {}


def _load(name: str):
    if name not in _CACHE:
        _CACHE[name] = wsoft.load_scene(scene_path(IZB[name][0]))
    return _CACHE[name]


def _tri_mask(scene, prefix: str) -> np.ndarray:
    hit = np.array([p == prefix or p.startswith(prefix + "/") for p in scene.prims], bool)
    return hit[scene.tri_prim]


def _area_volume(scene, mask: np.ndarray) -> tuple[float, float]:
    """Surface area and enclosed volume of the (closed, outward-wound) triangles in mask."""
    p = scene.points[scene.triangles[mask]].astype(np.float64)  # (T, 3, 3)
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * float(np.linalg.norm(cr, axis=1).sum())
    vol = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0
    return area, vol


def _extent(scene, mask: np.ndarray) -> np.ndarray:
    q = scene.points[np.unique(scene.triangles[mask])]
    return q.max(axis=0) - q.min(axis=0)


@pytest.mark.parametrize("name", list(IZB))
def test_izb_scene_loads(name):
    _file, lo, hi = IZB[name]
    s = _load(name)
    assert s.up_axis == "Z" and s.meters_per_unit == 1.0
    assert not s.warnings, s.warnings
    assert lo <= s.triangle_count <= hi, s.triangle_count
    assert np.isfinite(s.points).all()
    assert [c.path for c in s.cameras] == ["/World/Camera"]
    assert not s.cameras[0].orthographic
    assert [(lt.path, lt.kind) for lt in s.lights] == [("/World/Light", LIGHT_POINT)]
    assert not s.skipped_lights


def test_tower_bars_are_thin_and_closed():
    s = _load("tower")
    ground = _tri_mask(s, "/World/Ground")
    assert int(ground.sum()) == 2
    gpts = s.points[np.unique(s.triangles[ground])]
    assert np.all(gpts[:, 2] == 0.0)
    assert np.allclose(gpts[:, :2].min(axis=0), -8.0) and np.allclose(gpts[:, :2].max(axis=0), 8.0)
    tower = _tri_mask(s, "/World/Tower")
    assert s.tri_closed[tower].all()
    tp = s.points[np.unique(s.triangles[tower])]
    assert tp[:, 2].min() >= -0.05 and 4.0 <= tp[:, 2].max() <= 5.0  # stands on the ground, ~4 tall
    assert np.all(np.abs(tp[:, :2]) <= 1.6)  # footprint ~1.6 x 1.6, crossarms to |x| = 1.5
    for group, (t_lo, t_hi) in {"Legs": (0.03, 0.04), "Rings": (0.018, 0.03),
                                "Braces": (0.018, 0.025), "Arms": (0.018, 0.03)}.items():
        m = _tri_mask(s, "/World/Tower/" + group)
        assert m.any(), group
        area, vol = _area_volume(s, m)
        assert vol > 0.0, group  # outward-wound
        thick = 4.0 * vol / area  # a bar of square cross-section t: volume / area ~ t / 4
        assert t_lo <= thick <= t_hi, (group, thick)
        assert _extent(s, m).max() > 40.0 * thick, group  # long thin bars over the whole tower
    # the light is above the tower and off to the side, so the shadow falls on the ground
    light = s.lights[0]
    assert light.position[2] > tp[:, 2].max() + 1.0
    assert np.hypot(light.position[0], light.position[1]) > 2.0


def test_tunnel_fan_geometry():
    s = _load("tunnel_fan")
    walls = {"Floor": (2, 0.0, (0, 0, 1)), "Ceiling": (2, 2.0, (0, 0, -1)),
             "WallRight": (1, -1.0, (0, 1, 0)), "WallLeft": (1, 1.0, (0, -1, 0))}
    for name, (axis, value, inward) in walls.items():
        m = _tri_mask(s, "/World/Tunnel/" + name)
        assert m.sum() >= 100, name  # a grid of quads
        p = s.points[s.triangles[m]].astype(np.float64)
        assert np.all(np.abs(p[..., axis] - value) < 1e-6), name
        assert p[..., 0].min() == pytest.approx(0.0, abs=1e-6) and p[..., 0].max() == pytest.approx(12.0)
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        assert np.all(n @ np.asarray(inward, float) > 0.0), name  # normals face into the tunnel
        assert not s.tri_double_sided[m].any()
    blades = _tri_mask(s, "/World/Fan/Blades")
    assert int(blades.sum()) == 6 * 12  # six closed 8-point boxes
    assert s.tri_closed[blades].all()
    area, vol = _area_volume(s, blades)
    assert 0.015 <= 2.0 * vol / area <= 0.03  # flat blades: volume / area ~ thickness / 2
    fan = s.points[np.unique(s.triangles[_tri_mask(s, "/World/Fan")])]
    assert 11.5 <= fan[:, 0].min() and fan[:, 0].max() <= 12.1  # in the far opening
    r = np.hypot(fan[:, 1], fan[:, 2] - 1.0)
    assert 0.9 <= r.max() < 1.0  # nearly fills the 2 x 2 cross-section
    light = s.lights[0]
    assert 12.5 <= light.position[0] <= 15.0 and np.allclose(light.position[1:], (0.0, 1.0))
    eye = s.cameras[0].to_world[:3, 3]
    look = -s.cameras[0].to_world[:3, 2]
    assert eye[0] < 1.0 and np.all(np.abs(eye[1:] - (0.0, 1.0)) < 0.5)  # inside, at the near end
    assert look[0] > 0.99  # looking down +X, nearly along the walls


def _render(name: str, device: str):
    """V of ``hard`` and of the exact ``reference`` (a point light: one ray per pixel), the
    covered pixels, and the G-buffer positions, at 96 x 72."""
    s = _load(name)
    f = wsoft.render(s, "hard", width=96, height=72, device=device)
    ref = wsoft.render(s, "reference", width=96, height=72, device=device, samples=1, jitter=False)
    V, R, cov = f.V, ref.V, f["A"] > 0
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], axis=-1)
    assert np.all(np.isin(V[cov], (0.0, 1.0))) and np.all(np.isin(R[cov], (0.0, 1.0)))  # hard shadows
    # the shadow map agrees with the exact answer but for a few pixels (thin bars, grazing walls)
    assert np.count_nonzero((V != R) & cov) <= 0.05 * np.count_nonzero(cov)
    return V, R, cov, P


def test_tower_hard_render_shows_the_lattice_shadow(device):
    V, R, cov, P = _render("tower", device)
    ground = cov & (np.abs(P[..., 2]) < 1e-3) & (np.abs(P[..., 0]) + np.abs(P[..., 1]) > 2.0)
    assert ground.sum() > 0.5 * cov.sum()
    v = V[ground]
    assert (v == 0.0).any() and (v == 1.0).any()  # shadowed and lit ground in the hard render
    shadow = ground & (R == 0.0)
    assert 0.02 <= shadow.sum() / ground.sum() <= 0.4
    # the shadow falls away from the light (toward -x, +y); the ground under the light is lit
    assert np.all(P[shadow][:, 0] < 1.0) and np.all(P[shadow][:, 1] > -1.0)
    # high frequency: within the shadow's bounding box, lit gaps between the bars' shadows
    ys, xs = np.nonzero(shadow)
    win = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    assert 0.2 <= float(R[win][ground[win]].mean()) <= 0.9


def test_tunnel_hard_render_streams_blade_shadows(device):
    V, R, cov, P = _render("tunnel_fan", device)
    assert cov.sum() > 0.9 * V.size  # the walls fill the view but for the far opening
    surfaces = {
        "floor": np.abs(P[..., 2]) < 1e-3,
        "ceiling": np.abs(P[..., 2] - 2.0) < 1e-3,
        "right": np.abs(P[..., 1] + 1.0) < 1e-3,
        "left": np.abs(P[..., 1] - 1.0) < 1e-3,
    }
    for name, m in surfaces.items():
        v = V[cov & m]
        assert (v == 0.0).any() and (v == 1.0).any(), name
    # the wedges reach far down the tunnel toward the camera: lit and shadowed walls at x < 4
    near = cov & (P[..., 0] < 4.0)
    assert near.sum() > 0.3 * cov.sum()
    assert 0.2 <= float(R[near].mean()) <= 0.8
