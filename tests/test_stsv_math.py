"""The STSV per-triangle maths (wsoft.accel.stsv) against brute force in NumPy: the J/S
transmittance lookup against Möller–Trumbore, the shadow volume against many light samples."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from wsoft.accel.stsv import points_in_volumes, sample_blocked, s_triangle, receiver_matrix, stsv_lookup, stsv_volumes
from wsoft.scene.device import upload_scene
from wsoft.scene.surfaces import Surfaces, surface_present
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_RECT, LIGHT_SPHERE, Light, Material, Scene, Texture


def moller_trumbore(v0, v1, v2, o, d):
    """Rows: (t, u, v) of the ray o + t d against the plane of v0 v1 v2 (u: weight of v1, v; of v2)."""
    e1, e2 = v1 - v0, v2 - v0
    pv = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pv)
    inv = 1.0 / det
    tv = o - v0
    u = np.einsum("ij,ij->i", tv, pv) * inv
    qv = np.cross(tv, e1)
    v = np.einsum("ij,ij->i", d, qv) * inv
    t = np.einsum("ij,ij->i", e2, qv) * inv
    return t, u, v


def test_lookup_equals_ray_triangle(device):
    rng = np.random.default_rng(7)
    n = 20000
    tri = rng.uniform(-1, 1, (n, 3, 3))
    uvs = rng.uniform(-2, 3, (n, 3, 2))
    p = rng.uniform(-3, 3, (n, 3))
    s = rng.uniform(-3, 3, (n, 3))
    uv, bary, hit = stsv_lookup(tri, uvs, p, s, device=device)
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    t, u, v = moller_trumbore(v0, v1, v2, p, s - p)
    n_hat = np.cross(v1 - v0, v2 - v0)
    area = np.linalg.norm(n_hat, axis=1)
    cos = np.abs(np.einsum("ij,ij->i", n_hat / area[:, None], (s - p) / np.linalg.norm(s - p, axis=1)[:, None]))
    well = (area > 0.05) & (cos > 0.05)  # float32 conditioning: no slivers, no grazing segments
    bf = (t >= 0) & (t <= 1) & (u >= 0) & (v >= 0) & (u + v <= 1)
    margin = np.minimum.reduce([np.abs(u), np.abs(v), np.abs(1 - u - v), np.abs(t - 1), np.abs(t)])
    clear = well & (margin > 1e-5)
    assert np.array_equal(hit[clear], bf[clear])
    assert bf[clear].sum() > 200 and (~bf[clear]).sum() > 5000  # hits and misses both tested
    both = clear & bf
    ref_uv = uvs[:, 0] + u[:, None] * (uvs[:, 1] - uvs[:, 0]) + v[:, None] * (uvs[:, 2] - uvs[:, 0])
    assert np.max(np.abs(uv[both] - ref_uv[both])) < 1e-4
    assert np.max(np.abs(bary[both] - np.stack([1 - u - v, u, v], 1)[both])) < 1e-4


@wp.kernel
def blocked_both_ways(
    cut: Surfaces,
    tri: wp.array[wp.vec3],
    tri_uv: wp.array[wp.vec2],
    p: wp.array[wp.vec3],
    s: wp.array[wp.vec3],
    # outputs
    by_stsv: wp.array[wp.int32],
    by_bary: wp.array[wp.int32],
):
    i = wp.tid()
    st = s_triangle(tri[0], tri[1], tri[2], tri_uv[0], tri_uv[1], tri_uv[2])
    J = receiver_matrix(st, p[i])
    by_stsv[i] = int(sample_blocked(cut, 0, st, J, p[i], s[i]))
    h = J * (s[i] - p[i])
    ok = h[0] >= 0.0 and h[1] >= 0.0 and h[2] >= h[0] + h[1] and h[2] >= 1.0
    by_bary[i] = 0
    if ok:
        by_bary[i] = int(surface_present(cut, 0, (h[2] - h[0] - h[1]) / h[2], h[0] / h[2], h[1] / h[2]))


def fence_scene():
    """One cutout triangle with a striped alpha texture."""
    img = np.zeros((16, 16), np.float32)
    img[:, ::4] = 1.0
    img[::5, :] = 1.0
    pts = np.array([(-1, -1, 0), (2, -1, 0), (-1, 2, 0)], np.float32)
    uv = np.array([[(0, 0), (3, 0), (0, 3)]], np.float32)
    return Scene(path="t", points=pts, triangles=np.array([(0, 1, 2)], np.int32), tri_prim=np.zeros(1, np.int32),
                 tri_material=np.zeros(1, np.int32), tri_uv=uv, tri_double_sided=np.ones(1, bool), prims=["/f"],
                 materials=[Material(path="/m", opacity_threshold=0.5, texture=0)], textures=[Texture(asset="a", data=img)])


def test_alpha_lookup_equals_surface_present(device):
    """Equation 5's texture coordinate gives the alpha test the barycentric one does."""
    sc = fence_scene()
    ds = upload_scene(sc, device)
    rng = np.random.default_rng(3)
    n = 20000
    p = np.c_[rng.uniform(-1, 1.5, (n, 2)), rng.uniform(-3, -0.5, n)]
    s = np.c_[rng.uniform(-1, 1.5, (n, 2)), rng.uniform(0.5, 3, n)]
    out = [wp.zeros(n, dtype=wp.int32, device=device) for _ in range(2)]
    wp.launch(blocked_both_ways, dim=n, inputs=[ds.cutouts, wp.array(sc.points, dtype=wp.vec3, device=device),
                                                 wp.array(sc.tri_uv.reshape(-1, 2), dtype=wp.vec2, device=device),
                                                 wp.array(p.astype(np.float32), dtype=wp.vec3, device=device),
                                                 wp.array(s.astype(np.float32), dtype=wp.vec3, device=device)],
              outputs=out, device=device)
    a, b = out[0].numpy(), out[1].numpy()
    assert 0.2 < a.mean() < 0.8  # some samples pass through the holes, some are blocked
    assert np.mean(a != b) < 1e-3  # equal up to float rounding at the alpha threshold


def ball_samples(rng, light: Light, k: int) -> np.ndarray:
    """k points of the light (rect: on the rectangle; sphere: in the ball) or, distant, directions in its cone."""
    if light.kind == LIGHT_RECT:
        c = rng.uniform(-1, 1, (k, 2)) * np.asarray(light.half_size)
        return light.position + c[:, :1] * light.frame[:, 0] + c[:, 1:] * light.frame[:, 1]
    if light.kind == LIGHT_SPHERE:
        d = rng.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return light.position + d * light.radius * rng.uniform(0, 1, (k, 1)) ** (1 / 3)
    cos_max = math.cos(math.radians(0.5 * light.angle_deg))
    z = rng.uniform(cos_max, 1.0, k)
    phi = rng.uniform(0, 2 * math.pi, k)
    r = np.sqrt(1 - z * z)
    return (np.cos(phi) * r)[:, None] * light.frame[:, 0] + (np.sin(phi) * r)[:, None] * light.frame[:, 1] + z[:, None] * light.frame[:, 2]


def occluded_by_samples(tri, x, samples, distant: bool) -> np.ndarray:
    """[M] bool: does the segment from x[j] to some light sample (distant: along some direction,
    1e3 long) cross the triangle?"""
    out = np.zeros(len(x), bool)
    v0, v1, v2 = (np.broadcast_to(tri[k], x.shape) for k in range(3))
    for smp in samples:
        d = np.broadcast_to(smp * 1e3, x.shape) if distant else smp - x
        t, u, v = moller_trumbore(v0, v1, v2, x, d)
        out |= (t > 0) & (t <= 1) & (u >= 0) & (v >= 0) & (u + v <= 1)
    return out


def make_light(kind: int, pos, size: float, aim=(0.0, 0.0, -1.0)) -> Light:
    z = -np.asarray(aim, float) / np.linalg.norm(aim)
    x = np.cross([0.0, 1.0, 0.3], z)
    x /= np.linalg.norm(x)
    frame = np.stack([x, np.cross(z, x), z], 1)
    if kind == LIGHT_RECT:
        return Light(path="/L", kind=kind, position=np.asarray(pos, float), frame=frame, half_size=(size, 0.6 * size))
    if kind == LIGHT_SPHERE:
        return Light(path="/L", kind=kind, position=np.asarray(pos, float), frame=frame, radius=size)
    return Light(path="/L", kind=LIGHT_DISTANT, position=np.zeros(3), frame=frame, angle_deg=size)


# (light, where the random triangles are) — the last local case has the light straddling many
# triangles' planes (both sides lit, two volumes)
CASES = {
    "sphere": (make_light(LIGHT_SPHERE, (0.3, -0.2, 4.0), 0.8), 1.0),
    "rect": (make_light(LIGHT_RECT, (-0.5, 0.4, 3.5), 1.0, aim=(0.2, -0.1, -1.0)), 1.0),
    "distant": (make_light(LIGHT_DISTANT, None, 12.0, aim=(-0.3, 0.2, -1.0)), 1.0),
    "straddle": (make_light(LIGHT_SPHERE, (0.0, 0.0, 1.6), 0.7), 1.0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_volume_is_conservative_and_not_too_loose(case):
    """For random triangles (z in [0, 2]) and random points (a box around them and their shadows):

    * exact claim: every point that some light sample sees blocked by the triangle lies inside the
      volume (no slack at all, apart from float32 rounding: 1e-4 of a plane);
    * not vacuous: many points are inside and blocked;
    * tightness (a bound, not a claim of the paper): of the points inside the volume, at least
      ``frac`` are blocked by one of the 400 samples, for this light (the volume's planes are
      tangent to the light's bounding ball, so a rect light's volume is looser)."""
    light, _ = CASES[case]
    rng = np.random.default_rng(11)
    distant = light.kind == LIGHT_DISTANT
    samples = ball_samples(rng, light, 400)
    x = rng.uniform((-4, -4, -2), (4, 4, 2.5), (6000, 3))
    blocked_total = inside_total = inside_blocked = 0
    both = 0
    for k in range(12):
        c = rng.uniform((-1, -1, 0), (1, 1, 2))
        tri = c + rng.normal(0, 0.6, (3, 3))
        planes, sides = stsv_volumes(tri[None].astype(np.float32), light)
        both += int(sides[0] == 3)
        inside = points_in_volumes(planes, x, slack=1e-4)[0]
        blocked = occluded_by_samples(tri, x, samples, distant)
        assert not np.any(blocked & ~inside), f"triangle {k}: a blocked point outside the volume"
        blocked_total += blocked.sum()
        inside_total += inside.sum()
        inside_blocked += (inside & blocked).sum()
    assert blocked_total > 500
    frac = {"sphere": 0.4, "rect": 0.25, "distant": 0.1, "straddle": 0.7}[case]  # measured: 0.49, 0.31, 0.13 (grazing triangles), 0.85
    assert inside_blocked / inside_total > frac, inside_blocked / inside_total
    if case == "straddle":
        assert both >= 2  # both sides lit really happened


def test_point_in_volume_matches_brute_force_in_umbra_and_far_outside():
    """Against a brute force on a fixed triangle under a sphere light: points in the umbra (every
    sample blocked) are inside; points whose segments to *all* of the light's bounding ball miss the
    triangle by a margin (tested with the ball's samples inflated by 10 %) are mostly outside."""
    light = make_light(LIGHT_SPHERE, (0.0, 0.0, 4.0), 0.5)
    tri = np.array([(-1.0, -1.0, 1.0), (1.2, -0.8, 1.2), (0.0, 1.1, 0.9)])
    rng = np.random.default_rng(5)
    samples = ball_samples(rng, light, 300)
    x = rng.uniform((-3, -3, -1), (3, 3, 0.8), (8000, 3))
    planes, sides = stsv_volumes(tri[None].astype(np.float32), light)
    assert sides[0] == 1
    inside = points_in_volumes(planes, x)[0]
    counts = np.zeros(len(x), int)
    for smp in samples:
        t, u, v = moller_trumbore(*(np.broadcast_to(tri[k], x.shape) for k in range(3)), x, smp - x)
        counts += (t > 0) & (t <= 1) & (u >= 0) & (v >= 0) & (u + v <= 1)
    umbra = counts == len(samples)
    assert umbra.sum() > 100 and inside[umbra].all()
    big = make_light(LIGHT_SPHERE, (0.0, 0.0, 4.0), 0.55)
    none = ~occluded_by_samples(tri, x, ball_samples(rng, big, 600), False)
    assert none.sum() > 1000
    assert inside[none].mean() < 0.05  # the volume hugs the penumbra: few clearly unshadowed points inside


def test_fence_mesh_hides_what_the_perforated_fence_hides():
    """Fig. 11 on equal terms: ``fence_mesh``'s strips lie in the texture's plane (y = 0) and cover
    exactly the fence texture's opaque texels, so from any point (the light's samples included)
    they hide what ``fence_perforated``'s alpha test hides. Checked texel by texel over the whole
    fence (2048 x 1152 texels), and that the strips (each ``FENCE_SEGMENTS`` quads) do not overlap."""
    from wsoft.stages.scenes.stsv import FENCE_BASE, FENCE_CELLS, FENCE_SEGMENTS, FENCE_SIZE, FENCE_TILE, fence_tile, fence_wires

    pts, counts, idx = fence_wires()
    pts = np.asarray(pts)
    assert np.all(pts[:, 1] == 0.0)  # flat: no depth to widen the silhouette seen from aside
    assert set(counts) == {4} and 2 * len(counts) == 223_584
    nu, nv = FENCE_CELLS
    texel = FENCE_SIZE[0] / nu / FENCE_TILE
    q = pts[np.asarray(idx).reshape(-1, FENCE_SEGMENTS * 4)]  # [strips, the corners of its quads, 3]
    x0 = np.rint((q[:, :, 0].min(1) + FENCE_SIZE[0] / 2) / texel).astype(int)
    x1 = np.rint((q[:, :, 0].max(1) + FENCE_SIZE[0] / 2) / texel).astype(int)
    z0 = np.rint((q[:, :, 2].min(1) - FENCE_BASE) / texel).astype(int)
    z1 = np.rint((q[:, :, 2].max(1) - FENCE_BASE) / texel).astype(int)
    for lo, hi, v in ((x0, x1, q[:, :, 0] + FENCE_SIZE[0] / 2), (z0, z1, q[:, :, 2] - FENCE_BASE)):
        assert np.abs(np.concatenate([lo, hi]) * texel - np.concatenate([v.min(1), v.max(1)])).max() < 1e-9  # on texel borders
    cover = np.zeros((nv * FENCE_TILE, nu * FENCE_TILE), int)
    for a, b, c, d in zip(x0, x1, z0, z1):
        cover[c:d, a:b] += 1
    assert cover.max() == 1  # no strip overlaps another
    want = np.tile(fence_tile(), (nv, nu))  # the tile is symmetric: its orientation does not matter
    assert np.array_equal(cover == 1, want)


def test_dcs_alpha_transmittance_scales_the_binary_shadow(device, tmp_path):
    """``dcs transmittance=alpha`` (the paper's general case): a perforated card whose texture's
    alpha is 0.4 everywhere lets 0.6 of every light sample it hides through, so per pixel
    V_alpha = 1 - 0.4 (1 - V_binary) on the same samples (the binary test calls the card opaque,
    its threshold 0.3 being below the alpha); binary stays the default."""
    from PIL import Image
    import wsoft
    from wsoft.stages.builders import add_camera, add_cutout_material, add_mesh, add_quad, add_rect_light, make_stage

    Image.fromarray(np.full((8, 8, 4), 102, np.uint8)).save(tmp_path / "alpha.png")  # 102 / 255 = 0.4
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    mat = add_cutout_material(st, "/World/Looks/Card", (0.5, 0.5, 0.5), str(tmp_path / "alpha.png"), threshold=0.3)
    quad = ([(-0.8, -0.8, 1.0), (0.8, -0.8, 1.0), (0.8, 0.8, 1.0), (-0.8, 0.8, 1.0)], [4], [0, 1, 2, 3])
    add_mesh(st, "/World/Card", quad, True, mat, st=np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32))
    add_rect_light(st, "/World/Light", (0, 0, 3), 1.0, 1.0)
    add_camera(st, "/World/Cam", (0, -4.0, 5.0), (0, 0, 0), focal=20)
    scene = wsoft.load_scene(st)
    kw = {"width": 64, "height": 48, "device": device, "samples": 16}
    binary = wsoft.render(scene, "dcs", **kw)
    alpha = wsoft.render(scene, "dcs", transmittance="alpha", **kw)
    assert np.array_equal(wsoft.render(scene, "dcs", transmittance="binary", **kw).V, binary.V)
    pen = (binary["A"] > 0) & (binary.V > 0.05) & (binary.V < 0.95)
    assert pen.sum() > 50 and (binary.V < 0.01).sum() > 50  # penumbra and umbra are there
    assert np.abs(alpha.V - (1.0 - 0.4 * (1.0 - binary.V))).max() < 2e-3
    with pytest.raises(Exception, match="transmittance"):
        wsoft.render(scene, "dcs", transmittance="fractional", **kw)
