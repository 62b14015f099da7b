"""``csm``: cascaded shadow maps for a distant light, with practical or sample-distribution
(SDSM) partitions, stable (texel-snapped) cascades, a blend band and PCF or PCSS filtering.

The camera's depth range is cut into ``cascades`` slices (:mod:`wsoft.lightspace.cascades`); each
gets its own orthographic map of ``map_size`` texels a side along the light, so near receivers get
small texels and far ones large:

* ``partition=practical``: splits ``s_i = lam n (f/n)^(i/N) + (1 - lam)(n + (f - n) i/N)``
  (``lam`` = ``split_lambda``) between the camera's near clipping plane ``n`` and the farthest
  visible sample's depth ``f``; each cascade's region is the camera frustum's slice between its
  splits.
* ``partition=sdsm`` (the default; Lauritzen, Salvi and Lefohn 2011; the variant implemented: logarithmic
  partitions over ``[d_min, d_max]`` of the G-buffer's sampled depths, with tight per-partition
  light-space bounds): a chunked reduction over the G-buffer (:mod:`wsoft.accel.depth_reduce`,
  per-block partial rows combined in NumPy) finds the visible samples' depth range, splits it
  logarithmically, and bounds the samples of each slice in light space; each cascade's region is
  that bound, so no texel is spent where nothing is seen (the sky, hidden slices).

Each cascade's window (``stable``):

* ``stable=true`` (the default): a square around the region (practical: around the frustum
  slice's bounding sphere, which does not change as the camera turns; sdsm: around the samples'
  bound, its larger side), its half-side rounded up on the 2^(1/4) ladder and its centre on whole texels of a light-space grid anchored
  at the world origin, depth range snapped (:mod:`wsoft.lightspace.stable`): a camera that moves
  by less than a texel leaves every texel where it was, and a static receiver's V does not change;
* ``stable=false``: the region's tight light-space box (practical: the slice's corners clipped to
  the visible samples' bounds), the light's axes turned about its direction so that x follows the
  camera's view direction (:func:`facing_axes`: a depth slice is a narrow band across x): smaller
  texels, not square, that slide and turn with the camera (shimmer in motion).

Every window grows by ``tan(angle / 2) (z_far - z_caster)`` for casters of the sun's cone beyond
the receivers; its depth range starts at the nearest caster over it
(:func:`~wsoft.lightspace.fit.distant_caster_depth`).

A receiver uses the cascade whose slice holds its camera depth; in the last ``blend`` of a
cascade's depth range (the band before the next split) V is lerped toward the next cascade's,
which also maps that band, so shadows do not step at the splits.

Filtering (``filter``): ``pcf`` — ``taps`` comparisons over ``radius`` texels of the cascade's map
(its width in world units grows with the cascade); ``pcss`` — the blocker search, penumbra and
light-shaped filter of ``pcss`` (:func:`~wsoft.accel.pcss_filter.pcss_filter`) on the cascade's
map: the sun's cone (``angle``) sets the penumbra in world units, and the search and filter
half-widths in texels follow each cascade's texel size (clamped to ``[min_radius, max_radius]``).

Depth bias, per cascade ``k`` of texel width ``t_k`` (world units) and filter half-width ``r``
(texels): each tap compares the receiver's tangent plane at the tap's texel centre, nearer by
``plane_slope_bias`` of the plane's depth step per texel (the slope-scaled receiver-plane bias,
:func:`~wsoft.lightspace.view.receiver_tap_depth`: it grows with the tap's distance and the
receiver's slope), less ``b = bias * extent + texel_bias * t_k * (1 + r)`` (extent: the frame's
diagonal): a constant that grows with the texel size and the filter radius, for the curvature of
receivers the tangent plane does not follow.

Counters (``stats["counters"]["techniques"]["csm"][light]``): ``partition``, ``splits`` (camera
depths), ``texel_size`` (world units per texel, per cascade), ``cascade_samples`` (visible samples
per cascade's region), ``map_bytes`` (all cascade maps), ``cascades_drawn``.

Example::

    frame = wsoft.render(scene, "csm", width=640, height=480, cascades=4, partition="sdsm", map_size=1024)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.depth_reduce import cascade_bounds, sample_depth_range
from wsoft.accel.filters import pcf_visibility, taps_on
from wsoft.accel.pcss_filter import pcss_filter
from wsoft.lightspace.cascades import PARTITIONS, blend_band, cascade_ranges, cascade_window, log_splits, practical_splits, slice_corners, slice_sphere
from wsoft.lightspace.fit import distant_axes, distant_caster_depth
from wsoft.lightspace.light import LightKernel, light_kernel
from wsoft.lightspace.stable import snapped_depths
from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU, frame_extent_of_bounds, map_coords, texel_size, to_frame, view_dir
from wsoft.parallel import launch_chunked
from wsoft.params import check_ranges
from wsoft.raster.depth_map import rasterize
from wsoft.raster.gbuffer import GBufferGPU, gb_receiver
from wsoft.scene.types import LIGHT_DISTANT
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param

FILTERS = ("pcf", "pcss")
DEPTH_SLACK = 1e-5  # a cascade's region reaches this fraction of the farthest depth past its slice's ends


@dataclass(frozen=True)
class CSMParams:
    cascades: int = param(4, "cascades (maps) over the camera's depth range", range=(1, 8))
    partition: str = param("sdsm", "splits: practical (log/linear blend by split_lambda between the camera's near plane and the farthest "
                                   "visible sample) or sdsm (log splits over the visible samples' depth range, each cascade's window the "
                                   "tight light-space bounds of its samples)", choices=PARTITIONS)
    split_lambda: float = param(0.5, "partition=practical: weight of the logarithmic split against the uniform one", range=(0.0, 1.0))
    stable: bool = param(True, "stable cascades: bounding-sphere windows, radius on a 2^(1/4) ladder, origin on whole texels (no shimmer "
                               "under small camera moves); false: tight boxes")
    map_size: int = param(1024, "texels per side of each cascade's map", range=(256, 8192))
    blend: float = param(0.1, "width of the blend band before each split, as a fraction of the cascade's depth range", range=(0.0, 0.5))
    filter: str = param("pcss", "pcf (fixed kernel of radius texels) or pcss (blocker search and penumbra from the sun's angle)",
                        choices=FILTERS)
    radius: float = param(1.5, "filter=pcf: kernel half-width in texels of each cascade's map", range=(0.0, 64.0))
    taps: int = param(16, "filter=pcf: depth comparisons per sample (a perfect square for the grid pattern)", range=(1, 1024))
    pattern: str = param("grid", "tap pattern: grid or poisson", choices=("grid", "poisson"))
    blocker_samples: int = param(16, "filter=pcss: taps of the blocker search", range=(1, 1024))
    filter_samples: int = param(36, "filter=pcss: taps of the percentage-closer filter", range=(1, 4096))
    min_radius: float = param(1.0, "filter=pcss: smallest filter half-width in texels", range=(0.0, 512.0))
    max_radius: float = param(64.0, "filter=pcss: largest blocker-search and filter half-width in texels", range=(1.0, 1024.0))
    bias: float = param(1e-4, "constant depth bias as a fraction of the frame's extent", range=(0.0, 0.1))
    texel_bias: float = param(0.05, "depth bias in cascade texels times (1 + the filter's half-width in texels)", range=(0.0, 16.0))
    plane_slope_bias: float = param(0.25, "texels of the receiver's tangent-plane depth step per texel taken off at each tap", range=(0.0, 16.0))

    def __post_init__(self):
        check_ranges(self)
        if self.pattern == "grid":
            counts = (self.taps,) if self.filter == "pcf" else (self.blocker_samples, self.filter_samples)
            for n in counts:
                check(math.isqrt(n) ** 2 == n, f"the grid pattern needs square sample counts, not {n}")
        check(self.min_radius <= self.max_radius, "need min_radius <= max_radius")


@dataclass
class Cascades:
    """A frame's cascades of one light: per cascade its view and depth map (``[S, S]`` float32,
    ``DEPTH_CLEAR`` where empty; None for a cascade no visible sample falls in), the split depths
    ``[K + 1]``, the blend band widths ``[K]`` and texel sizes ``[K]`` (world units)."""

    views: list
    depths: list
    splits: np.ndarray
    band: np.ndarray
    texels: np.ndarray
    caster_min: list

    def arrays(self) -> dict[str, wp.array]:
        return {f"depth{k}": d for k, d in enumerate(self.depths) if d is not None}


@wp.func
def cascade_of(splits: wp.array[float], n: int, d: float) -> int:
    """The cascade whose slice ``[s_k, s_{k+1})`` holds camera depth ``d`` (the first before
    ``s_0``, the last beyond ``s_n``)."""
    k = int(0)
    for j in range(1, n):
        if d >= splits[j]:
            k = j
    return k


@wp.func
def cascade_weight(splits: wp.array[float], band: wp.array[float], n: int, k: int, d: float) -> float:
    """Cascade ``k``'s share of V at camera depth ``d``: 1 inside its slice, falling linearly to 0
    across the blend band at its far end (``band[k]`` wide), where the next cascade's rises from 0."""
    c = cascade_of(splits, n, d)
    w = float(0.0)
    if c == k:
        w = 1.0
        if k + 1 < n and band[k] > 0.0:
            w = 1.0 - (d - (splits[k + 1] - band[k])) / band[k]
    elif c == k - 1 and band[c] > 0.0:
        w = (d - (splits[k] - band[c])) / band[c]
    return wp.clamp(w, 0.0, 1.0)


@wp.kernel
def shade_cascade(
    offset: int,
    k: int,
    lv: ViewGPU,
    kern: LightKernel,
    depth: wp.array2d[float],
    gb: GBufferGPU,
    eye: wp.vec3,
    forward: wp.vec3,
    splits: wp.array[float],
    band: wp.array[float],
    n: int,
    use_pcss: int,
    btaps: wp.array[wp.vec2],
    nb: int,
    ftaps: wp.array[wp.vec2],
    nf: int,
    disk: int,
    radius: float,
    z_caster_min: float,
    bias: float,
    bias_per_texel: float,
    plane_slope: float,
    min_radius: float,
    max_radius: float,
    dmax: float,
    # outputs
    vis: wp.array[float],
):
    """Add cascade ``k``'s weighted visibility to ``vis`` (0 on every covered sample before the
    first cascade; the weights of a sample's cascades sum to 1)."""
    i = wp.tid() + offset
    r = gb_receiver(lv, gb, i)
    if r[3] == 0.0:
        return
    w = cascade_weight(splits, band, n, k, wp.dot(gb.pos[i] - eye, forward))
    if w <= 0.0:
        return
    pv = wp.vec3(r[0], r[1], r[2])
    nv = view_dir(lv, gb.nrm[i])
    v = float(1.0)
    if use_pcss != 0:
        v = pcss_filter(lv, kern, depth, pv, nv, btaps, nb, ftaps, nf, z_caster_min, bias, bias_per_texel, plane_slope, min_radius,
                        max_radius, dmax)[0]
    else:
        half = texel_size(lv) * radius
        v = pcf_visibility(lv, depth, pv, nv, map_coords(lv, pv), half, disk, ftaps, nf, bias + bias_per_texel * radius, 1, plane_slope,
                           dmax)
    vis[i] = vis[i] + w * v


class CSM(Technique):
    """Cascaded shadow maps (practical or SDSM partitions, stable cascades, blend bands, PCF or PCSS) for distant lights."""

    name = "csm"
    distant_angle_limit = 70.0  # its pcss filter: as pcss's
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "cascaded shadow maps for the sun: practical or SDSM splits, stable texel-snapped cascades, blend bands, PCF or PCSS"
    Params = CSMParams
    passes = (
        PassSpec("cascades", reads=("scene", "gbuffer"), writes=("csm_cascades",)),
        PassSpec("shadow", reads=("gbuffer", "csm_cascades"), writes=("visibility",)),
    )
    quick_params = {"map_size": 256}
    size_param = "map_size"
    distance_caveat = "the caster nearest the light in each texel of a cascade's map"
    quality = (Quality("cascades", (2, 4, 8), "more cascades: smaller texels near the camera, one more map each"),
               Quality("filter_samples", (16, 36, 100), "filter=pcss: more filter taps, smoother penumbrae, linearly more time"))
    tolerance = Tolerance(mae=0.0025, mae_penumbra=0.06)
    cylinder_model = "none: it shadows distant lights alone (a cylinder light is declined)"

    def supports(self, scene, light) -> str | None:
        if light.kind != LIGHT_DISTANT:  # the light's kind first: no other reason applies to a light it never renders
            return "csm cascades a distant light's orthographic map over the camera's depth range: use pcss or pcf for a local light"
        return super().supports(scene, light)

    def bake_support(self) -> str | None:
        return "csm splits its cascades by the camera's depth; a bake has no camera"

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        sk = ctx.scene_arrays()
        ckey = ctx.key("csm_cascades", light, variant=f"@{p.map_size}")
        out = ctx.visibility_key(light)
        counters = ctx.counters(light)

        def build(res):
            cs = fit_cascades(ctx, light, res[gbuf], p, counters)
            ds = res[sk]
            casting = ctx.scene.casting_triangles(light)
            for k, view in enumerate(cs.views):
                if view is None:
                    continue
                dm = rasterize(ds, view, alpha_tested=ctx.scene.has_cutouts, triangles=casting)
                cs.depths[k] = dm.depth
                d = dm.depth.numpy()
                covered = d[d < DEPTH_CLEAR]
                cs.caster_min[k] = float(covered.min()) if covered.size else float(view.far)
            counters["map_bytes"] = int(sum(d.size * 4 for d in cs.depths if d is not None))
            counters["cascades_drawn"] = int(sum(d is not None for d in cs.depths))
            return {ckey: cs}

        def shade(res):
            gb, cs = res[gbuf], res[ckey]
            dev = ctx.device
            ext = next((v.extent for v in cs.views if v is not None), 1.0)
            eye, fwd = camera_frame(ctx.camera)
            vis = wp.array(np.where(gb.prim.numpy() >= 0, 0.0, 1.0).astype(np.float32), dtype=float, device=dev)  # background lit
            pcss = p.filter == "pcss"
            bt = taps_on(dev, p.pattern, p.blocker_samples if pcss else 1)
            ft = taps_on(dev, p.pattern, p.filter_samples if pcss else p.taps)
            splits = wp.array(cs.splits.astype(np.float32), dtype=float, device=dev)
            band = wp.array(cs.band.astype(np.float32), dtype=float, device=dev)
            for k, view in enumerate(cs.views):
                if view is None:  # no visible sample in its slice: none has a weight in it
                    continue
                t = float(cs.texels[k])
                launch_chunked(
                    shade_cascade, gb.count,
                    inputs=[k, view.gpu(), light_kernel(light, view), cs.depths[k], gb.gpu(), wp.vec3(*eye), wp.vec3(*fwd), splits, band,
                            len(cs.views), int(pcss), bt.array, bt.count, ft.array, ft.count, int(p.pattern == "poisson"), p.radius,
                            cs.caster_min[k], p.bias * ext + p.texel_bias * t, p.texel_bias * t, p.plane_slope_bias, p.min_radius,
                            p.max_radius, light.shadow_distance],
                    outputs=[vis], device=dev, min_chunk=256,
                )
            return {out: ctx.visibility(vis)}

        ctx.add_pass(ctx.pass_name("csm_cascades", light, f"@{p.map_size}"), inputs=(sk, gbuf), outputs=(ckey,), run=build, stage="cascades",
                     light=light)
        return ctx.add_pass(ctx.pass_name("csm", light), inputs=(gbuf, ckey), outputs=(out,), run=shade, stage="shadow", light=light)


def camera_frame(camera) -> tuple[np.ndarray, np.ndarray]:
    """The camera's eye and unit forward direction (its −Z) in world space."""
    m = np.asarray(camera.to_world, np.float64)
    f = -m[:3, 2]
    return m[:3, 3].copy(), f / np.linalg.norm(f)


def camera_window(camera) -> tuple[float, float, float, float]:
    """The camera's window (l, r, b, t): tangents for a perspective camera, world units for an orthographic one."""
    (tx, ty), (ox, oy) = camera.tan_half, camera.offset
    return ox - tx, ox + tx, oy - ty, oy + ty


def facing_axes(axes: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """A distant light's view axes turned about its direction so that x lies along the camera's
    ``forward`` seen along the light: a slice of the camera's depth range is then a narrow band
    across x, and a tight box around it spends fewer texels (fitted cascades; a stable cascade keeps
    the light's own axes, which do not turn with the camera)."""
    f = np.array([forward @ axes[:, 0], forward @ axes[:, 1]])
    if not np.linalg.norm(f) > 1e-6:
        return axes
    c, s = f / np.linalg.norm(f)
    x = c * axes[:, 0] + s * axes[:, 1]
    y = -s * axes[:, 0] + c * axes[:, 1]
    return np.stack([x, y, axes[:, 2]], axis=1)


def fit_cascades(ctx, light, gb, p: CSMParams, counters: dict) -> Cascades:
    """The frame's cascades of ``light`` (their views; the maps are drawn by the caller): splits by
    ``p.partition``, windows by ``p.stable`` (module docstring). A cascade no visible sample falls
    in gets no view (None)."""
    cam = ctx.camera
    eye, fwd = camera_frame(cam)
    n = p.cascades
    count, d_min, d_max = sample_depth_range(gb.pos, gb.prim, eye, fwd)
    axes = distant_axes(light)
    if not p.stable:
        axes = facing_axes(axes, fwd)
    anchor = np.zeros(3) if ctx.origin is None else -np.asarray(ctx.origin, np.float64)
    if count == 0:
        splits = np.linspace(cam.clip[0], cam.clip[0] * 2.0, n + 1)
        counters.update(partition=p.partition, splits=splits.tolist(), texel_size=[0.0] * n, cascade_samples=[0] * n)
        return Cascades([None] * n, [None] * n, splits, np.zeros(n), np.zeros(n), [0.0] * n)
    d_max = max(d_max, d_min * (1.0 + 1e-6) + 1e-9)
    if p.partition == "sdsm":
        lo_d = max(d_min, 1e-6 * d_max)
        splits = log_splits(lo_d, d_max, n)
    else:
        near = min(max(float(cam.clip[0]), 1e-6 * d_max), d_min)
        splits = practical_splits(near, d_max, n, p.split_lambda)
    band = blend_band(splits, p.blend)
    ranges = cascade_ranges(splits, band)
    ranges[0, 0] = min(ranges[0, 0], d_min)  # both ends inclusive: every sample falls in some range
    ranges[-1, 1] = max(ranges[-1, 1], d_max)
    ranges += np.array([-1.0, 1.0]) * DEPTH_SLACK * d_max  # the shading kernel's float32 depths may round across a split
    cnt, lo, hi = cascade_bounds(gb.pos, gb.prim, eye, fwd, anchor, axes, ranges)
    seen = cnt > 0
    rlo, rhi = lo[seen].min(axis=0), hi[seen].max(axis=0)  # every visible sample, light space
    ext = frame_extent_of_bounds(anchor + axes @ rlo, anchor + axes @ rhi)  # the receivers' diagonal (a rotation keeps it)
    zr_min, zr_max = float(rlo[2]), float(rhi[2])
    scene = ctx.scene
    pts = scene.caster_points
    vp = to_frame(np.asarray(pts).reshape(-1, 3), anchor, axes) if pts is not None and len(pts) else None
    tan_a = math.tan(math.radians(0.5 * light.angle_deg)) if light.angle_deg > 0 else 0.0
    mesh = scene.caster_mesh()
    zc = distant_caster_depth(vp, (rlo[0], rhi[0], rlo[1], rhi[1]), zr_min, zr_max, tan_a, mesh, anchor, axes)
    grow = tan_a * max(zr_max - zc, 0.0)
    windows, texels, snaps = [], np.zeros(n), []
    cam_axes = np.asarray(cam.to_world, np.float64)[:3, :3].copy()
    cam_axes[:, 2] = fwd
    cwin = camera_window(cam)
    for k in range(n):
        if not seen[k]:
            windows.append(None)
            snaps.append({})
            continue
        a, b = ranges[k]
        if p.partition == "sdsm":
            win, t, snap = cascade_window(lo[k, :2], hi[k, :2], p.map_size, p.stable, grow, radius=0.5 * float(np.max(hi[k, :2] - lo[k, :2])))
        elif p.stable:
            tx = max(abs(cwin[0]), abs(cwin[1]))
            ty = max(abs(cwin[2]), abs(cwin[3]))
            c, r = slice_sphere(a, b, tx, ty, cam.orthographic)
            centre = to_frame((eye + fwd * c)[None], anchor, axes, threads=False)[0]
            win, t, snap = cascade_window(centre[:2], centre[:2], p.map_size, True, grow, radius=r)
        else:
            corners = to_frame(slice_corners(eye, cam_axes, a, b, cwin, cam.orthographic), anchor, axes, threads=False)
            clo = np.maximum(corners[:, :2].min(axis=0), rlo[:2])
            chi = np.minimum(corners[:, :2].max(axis=0), rhi[:2])
            win, t, snap = cascade_window(np.minimum(clo, chi), np.maximum(clo, chi), p.map_size, False, grow)
        windows.append(win)
        texels[k] = t
        snaps.append(snap)
    union = (min(w[0] for w in windows if w), max(w[1] for w in windows if w), min(w[2] for w in windows if w), max(w[3] for w in windows if w))
    zc = min(zc, distant_caster_depth(vp, union, zr_min, math.inf, 0.0, mesh, anchor, axes))
    lead = 1e-3 * ext
    z0, z1 = zc - lead, zr_max + lead
    if p.stable:
        z0, z1, _ = snapped_depths(z0, z1)
    views = []
    for k, win in enumerate(windows):
        if win is None:
            views.append(None)
            continue
        cx, cy = 0.5 * (win[0] + win[1]), 0.5 * (win[2] + win[3])
        hx, hy = 0.5 * (win[1] - win[0]), 0.5 * (win[3] - win[2])
        origin = anchor + axes @ np.array([cx, cy, z0])
        views.append(LightView(light_path=light.path, persp=False, origin=origin, axes=axes, window=(-hx, hx, -hy, hy), near=0.0,
                               far=float(z1 - z0), width=p.map_size, height=p.map_size, extent=ext, growth=float(grow),
                               snap=snaps[k] or None))
    counters.update(partition=p.partition, stable=p.stable, splits=[float(s) for s in splits], texel_size=[float(t) for t in texels],
                    cascade_samples=[int(c) for c in cnt], sample_depth_range=[float(d_min), float(d_max)])
    return Cascades(views, [None] * n, splits, band, texels, [0.0] * n)
