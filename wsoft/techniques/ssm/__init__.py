"""``ssm``: backprojection soft shadow mapping with quality scalability (Schwarz & Stamminger 2008).

The shadow map's texels are micro-occluders. For every receiver, the *search area* (where a
caster could hide part of the light) is found and refined with a pruning structure's depth
range; receivers in umbra or fully lit stop there. The others backproject the micro-occluders
of the area from the receiver onto the light and clip them to it; visibility is 1 minus the
covered share (a clamped sum of areas, or an occlusion bitmask over light samples).

* Occluders (``occluder``): ``micropatch`` (a texel at its depth, extended toward its left and
  bottom neighbours so their projections leave no gap), ``microquad`` (texel centres as the
  corners of a quad mesh, all four nearer than the receiver) and ``microrect`` (§5: extents and
  depths derived level by level by the greedy two-pass merge; two extra textures with full mip
  chains, :mod:`wsoft.accel.ssm_structures`). Merge partners are picked by depth difference,
  differences within ``microrect_tie`` counting as ties (a flat occluder's rasterized depth varies
  by float32 rounding, which must not pick them); a receiver reads every microrect whose extent
  reaches its search area (``gather``).
* Pruning (``structure``): ``hsm`` (min/max pyramid), ``mssm`` (ranges of every power-of-two
  neighbourhood of every texel) or ``ysm`` (the HSM plus an MSSM over HSM level ``n - 1`` of
  ``ysm_size`` texels per side), with ``refine`` iterations of search-area refinement.
* Budget (``budget`` = b_mo): at most ``b_mo`` micro-occluders per axis; the level is
  ``l = log2(search size / b_mo)`` (a *LOQ map*), level 0 with ``inf``. ``budget_map`` gives b_mo
  per pixel: an EXR (channel ``budget``, ``Y``, ``R`` or its only channel, resampled to the
  image) or ``radial`` (from ``budget`` at the centre to ``budget_min`` at the left and right
  borders, as the paper's Fig. 1d).
* Smooth LOQ (§4.2): the LOQ map is smoothed by a separable 11 x 11 (``smooth_radius = 5``)
  filter that stops at camera-depth jumps and at receivers that need no backprojection; the
  visibilities of levels ``floor(l)`` and ``ceil(l)`` are blended by the fraction. ``blend =
  false`` takes ``ceil(l)`` alone (the transition artifacts of Fig. 1a). Without a finite
  budget nothing is smoothed or blended (Table 2's note).
* Over-precision (§6): the queried region grows to the support of the level's micro-occluders.
* A light across the receiver's tangent plane: only its front part lights the receiver
  (:mod:`wsoft.lightspace.halfspace`); each backprojected area is clipped to the plane's line on
  the light and V is the front part's share less the covered area (``bitmask``: the samples behind
  the line are blocked from the start).
* Multisampling (§7, with ``pixel_samples`` > 1): ``msaa = interpolate`` computes visibility
  once per pixel, on its first covered sample, and resolves each sample whose camera depth is
  not within ``tau`` of it from the 4-neighbour whose depth is closest; ``single`` gives every
  sample the pixel's visibility; ``per_sample`` is the brute-force version. The G-buffer's
  4-sample pattern (:mod:`wsoft.raster.gbuffer`) puts each sample in its own row and column of
  the pixel (an n-rooks pattern, the property the rotated grid is chosen for).

Lights: rect lights exactly (the paper's case); disk and sphere lights by their bounding square
(the bitmask samples are mapped into the disk; area accumulation measures the square); distant
lights through the sun's cone in an orthographic map. Point lights (and suns of angle 0) cast
no soft shadow and are rejected.

Counters (``stats["counters"]``, prefix ``ssm[light].``): ``backprojecting_fraction`` (of covered
receivers) and ``backprojecting_fraction_all_pixels`` (of every receiver, background included),
``search_width_mean_texels`` (mean side of the backprojecting receivers' search areas),
``umbra_fraction``, ``lit_fraction``, ``occluders_mean``, ``occluders_stdev`` and ``occluders_max``
(micro-occluders processed per backprojecting receiver, both levels when blending),
``levels_used`` (histogram: receivers per level, a blended receiver counts at both),
``structure_build_ms``, ``microrect_build_ms`` and ``memory_bytes`` per structure.

Example::

    frame = wsoft.render(scene, "ssm", width=640, height=480, occluder="microrect",
                         visibility="bitmask", budget=10, budget_map="radial")
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.pyramid import build_minmax_pyramid
from wsoft.accel.ssm_structures import (
    MicroRects,
    PruningStructure,
    build_microrects,
    build_structure,
)
from wsoft.errors import ParameterError
from wsoft.lightspace.bitmask import PATTERN_ANY, PATTERN_JITTERED, PATTERN_REGULAR
from wsoft.lightspace.light import disk_shaped, light_kernel
from wsoft.lightspace.samples import SamplePattern
from wsoft.parallel import launch_chunked
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_POINT
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param
from wsoft.techniques.ssm.kernels import (
    OCC_MICROPATCH,
    OCC_MICROQUAD,
    OCC_MICRORECT,
    STATUS_BACKGROUND,
    STATUS_LIT,
    STATUS_PENUMBRA,
    STATUS_UMBRA,
    SSMSetup,
    backproject,
    pick_receivers,
    resolve_samples,
    search_areas,
    smooth_loq,
)

OCCLUDERS = {"micropatch": OCC_MICROPATCH, "microquad": OCC_MICROQUAD, "microrect": OCC_MICRORECT}
PATTERNS = ("regular", "jittered", "random")
MSAA_MODES = ("interpolate", "single", "per_sample")


@dataclass(frozen=True)
class SSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map (a power of two)", range=(256, 8192))
    occluder: str = param("micropatch", "micro-occluders: micropatch, microquad or microrect")
    visibility: str = param("bitmask", "light visibility: area (clamped sum of covered areas) or bitmask")
    bitmask_size: int = param(16, "light samples per side of the occlusion bitmask: 8, 16 or 32", range=(8, 32))
    pattern: str = param("jittered", "bitmask sample pattern: regular, jittered or random")
    structure: str = param("ysm", "search-area pruning: hsm, mssm or ysm")
    ysm_size: int = param(256, "texels per side of the YSM's MSSM part (a power of two)", range=(16, 8192))
    budget: float = param(16.0, "b_mo: micro-occluders per axis (inf: always level 0)", range=(1.0, math.inf))
    budget_map: str = param("", "per-pixel b_mo: '' (uniform), radial, or an EXR file")
    budget_min: float = param(5.0, "b_mo at the left and right borders with budget_map=radial", range=(1.0, 1.0e6))
    blend: bool = param(True, "smooth the LOQ map and blend levels floor(l) and ceil(l) (false: ceil(l) alone)")
    smooth_radius: int = param(5, "half-width of the LOQ smoothing in pixels (5: 11 x 11; 0: none)", range=(0, 32))
    depth_threshold: float = param(0.05, "relative camera-depth jump at which the LOQ smoothing stops", range=(1e-6, 100.0))
    refine: int = param(4, "search-area refinement iterations", range=(0, 16))
    overprecision: bool = param(True, "grow the queried region to the support of the level's micro-occluders (lit/umbra classification only)")
    gather: str = param("extent", "microrects at a coarse level: extent (every microrect whose extent reaches the search area, read from the (b+2)² cells that can hold one) or budget (the (b+1)² cells over the search area, as micropatches: misses extents reaching in from the +x and +y cells)")
    microrect_diagonal: str = param("paper", "microrects: who takes a diagonal neighbour the first pass leaves: paper (the +x+y one, §5.2) or nearest (the neighbour of nearest depth; not the paper's)")
    microrect_tie: float = param(1e-6, "microrects: relative depth difference within which two merge partners count as equally near (the rasterized depth of a flat occluder varies by a few float32 ulps; 0: exact comparison)", range=(0.0, 0.01))
    gap_fill: bool = param(True, "extend micropatches toward their left and bottom neighbours")
    msaa: str = param("interpolate", "with pixel_samples > 1: interpolate, single or per_sample")
    tau: float = param(0.01, "relative camera-depth difference below which a sample takes its pixel's visibility", range=(0.0, 100.0))
    bias: float = param(2e-4, "depth bias against the receiver's tangent plane, fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    seed: int = param(7, "seed of the jittered and random bitmask samples", range=(0, 2**31 - 1))

    def __post_init__(self):
        check_ranges(self)
        n = self.shadow_map_size
        check(n & (n - 1) == 0, f"shadow_map_size {n} must be a power of two in [256, 8192]")
        check(self.occluder in OCCLUDERS, f"occluder {self.occluder!r} is not one of {', '.join(OCCLUDERS)}")
        check(self.gather in ("extent", "budget"), f"gather {self.gather!r} is not extent or budget")
        check(self.microrect_diagonal in ("paper", "nearest"), f"microrect_diagonal {self.microrect_diagonal!r} is not paper or nearest")
        check(self.visibility in ("area", "bitmask"), f"visibility {self.visibility!r} is not area or bitmask")
        check(self.bitmask_size in (8, 16, 32), f"bitmask_size {self.bitmask_size} is not 8, 16 or 32")
        check(self.pattern in PATTERNS, f"pattern {self.pattern!r} is not one of {', '.join(PATTERNS)}")
        check(self.structure in ("hsm", "mssm", "ysm"), f"structure {self.structure!r} is not hsm, mssm or ysm")
        m = self.ysm_size
        check(m & (m - 1) == 0, f"ysm_size {m} must be a power of two >= 16")
        if self.budget_map == "radial":
            check(self.budget_min <= self.budget, f"budget_min {self.budget_min} must be in [1, budget]")
        if self.budget_map not in ("", "radial"):
            check(os.path.isfile(self.budget_map), f"budget_map file {self.budget_map!r} not found")
        check(self.msaa in MSAA_MODES, f"msaa {self.msaa!r} is not one of {', '.join(MSAA_MODES)}")


def light_samples(pattern: str, n: int, disk: bool, seed: int, device: str) -> tuple[wp.array, int]:
    """``n * n`` light samples in light coordinates (row-major: sample r * n + c in cell (c, r) for
    the regular and jittered patterns) on ``device``, and the bitmask's pattern code. On a disk
    light the samples are mapped into the unit disk and every one is tested."""
    pts = SamplePattern(pattern, n * n, seed=seed).light_coords(device, disk)
    if disk:
        return pts, PATTERN_ANY
    return pts, {"regular": PATTERN_REGULAR, "jittered": PATTERN_JITTERED}.get(pattern, PATTERN_ANY)


def budget_image(p: SSMParams, width: int, height: int) -> np.ndarray:
    """Per-pixel b_mo, ``[H, W]`` float32 (``inf`` where unbounded)."""
    if p.budget_map == "":
        return np.full((height, width), p.budget, np.float32)
    if p.budget_map == "radial":
        x = (np.arange(width) + 0.5) / width * 2 - 1
        row = p.budget - (p.budget - p.budget_min) * np.abs(x) if math.isfinite(p.budget) else np.where(np.abs(x) < 1, p.budget, p.budget_min)
        return np.broadcast_to(row.astype(np.float32), (height, width)).copy()
    from wsoft.io import read_exr

    try:
        ch = read_exr(p.budget_map)
    except (OSError, RuntimeError, ValueError) as exc:  # a broken or foreign file
        raise ParameterError(f"ssm: budget_map {p.budget_map!r} cannot be read as EXR ({exc})", file=p.budget_map) from None
    names = [k for k in ("budget", "Y", "R", "V") if k in ch] or sorted(ch)
    if not names:
        raise ParameterError("ssm: budget_map has no channel", file=p.budget_map)
    img = np.asarray(ch[names[0]], np.float32)
    if img.ndim == 3:
        img = img[..., 0]
    ys = (np.arange(height) * img.shape[0] // height).clip(0, img.shape[0] - 1)
    xs = (np.arange(width) * img.shape[1] // width).clip(0, img.shape[1] - 1)
    out = img[ys][:, xs]
    if not np.all(np.isfinite(out) | (out == np.inf)) or (out < 1).any():
        raise ParameterError("ssm: budget_map values must be >= 1 (or inf)", file=p.budget_map)
    return np.ascontiguousarray(out)


@dataclass
class SSMMaps:
    """What the structure pass builds from the depth map: the pruning structure, the pyramid the
    micro-occluders are read from (the HSM; a separate one with the MSSM), the microrects."""

    structure: PruningStructure
    occluders: PruningStructure
    microrects: MicroRects | None

    def arrays(self) -> dict[str, wp.array]:
        out = {f"{self.structure.kind}.{k}": v for k, v in self.structure.arrays().items()}
        if self.occluders is not self.structure:
            out["occluder_pyramid"] = self.occluders.pyr
        if self.microrects is not None:
            out.update(self.microrects.arrays())
        return out


@dataclass
class SSMSearch:
    """Per receiver (``layers * H * W``, laid out as the G-buffer's samples): search area, status,
    raw LOQ, camera depth, receiver -> G-buffer sample."""

    layers: int
    rid: wp.array
    area: wp.array
    status: wp.array
    loq_raw: wp.array
    cam: wp.array

    def arrays(self) -> dict[str, wp.array]:
        return {"area": self.area, "status": self.status, "loq_raw": self.loq_raw, "cam": self.cam, "rid": self.rid}


@dataclass
class SSMLoq:
    """The smoothed LOQ map (per receiver; a copy of the raw one when nothing is smoothed)."""

    loq: wp.array

    def arrays(self) -> dict[str, wp.array]:
        return {"loq": self.loq}


def build_maps(depth: wp.array, p: SSMParams, device: str) -> SSMMaps:
    st = build_structure(p.structure, depth, device, ysm_size=p.ysm_size)
    occ = st
    if p.structure == "mssm":
        pyr = build_minmax_pyramid(depth, device, skip_empty=False)
        occ = build_structure("hsm", depth, device, pyramid=pyr)
    mr = build_microrects(depth, device, p.microrect_diagonal, p.microrect_tie) if p.occluder == "microrect" else None
    return SSMMaps(st, occ, mr)


def receivers(gb, msaa: str, device: str) -> tuple[wp.array, int]:
    """Receiver -> G-buffer sample index (int32) and the number of layers: one receiver per pixel
    on its first covered sample, or every sample (``per_sample``)."""
    npix = gb.width * gb.height
    if gb.spp == 1 or msaa == "per_sample":
        return wp.array(np.arange(gb.count, dtype=np.int32), dtype=wp.int32, device=device), gb.spp
    rid = wp.empty(npix, dtype=wp.int32, device=device)
    launch_chunked(pick_receivers, npix, inputs=[gb.gpu()], outputs=[rid], device=device)
    return rid, 1


def msaa_resolve(vis_pix: wp.array, rid: wp.array, gb, tau: float, interpolate: bool, device: str) -> wp.array:
    """Per-sample visibility (flat, sample-major) from per-pixel visibility (§7's custom resolve);
    ``rid[p]``: the G-buffer sample pixel ``p``'s visibility was computed on."""
    n = gb.count
    out = wp.empty(n, dtype=float, device=device)
    launch_chunked(resolve_samples, n, inputs=[vis_pix, rid, gb.gpu(), float(tau), int(interpolate)], outputs=[out], device=device)
    return out


def run_search(setup: SSMSetup, maps: SSMMaps, gb, p: SSMParams, budget: np.ndarray, device: str) -> SSMSearch:
    """Kernel 1: search areas, classification and the raw LOQ map."""
    rid, layers = receivers(gb, p.msaa, device)
    n = rid.shape[0]
    b = np.broadcast_to(budget, (layers,) + budget.shape).ravel().astype(np.float32)
    s = SSMSearch(
        layers, rid, area=wp.empty(n, dtype=wp.vec4, device=device), status=wp.empty(n, dtype=wp.int32, device=device),
        loq_raw=wp.empty(n, dtype=float, device=device), cam=wp.empty(n, dtype=float, device=device),
    )
    g = maps.structure.gpu
    z_first = float(maps.occluders.pyr.numpy()[-1][0])  # the nearest depth of the whole map
    launch_chunked(search_areas, n, inputs=[setup, g, gb.gpu(), rid, wp.array(b, dtype=float, device=device), z_first],
                   outputs=[s.area, s.status, s.loq_raw, s.cam], device=device, min_chunk=256)
    return s


def run_smoothing(s: SSMSearch, gb, p: SSMParams, smooth: bool, device: str) -> SSMLoq:
    """Kernel 2: the separable LOQ smoothing into a new array (a copy of the raw LOQ without it)."""
    n = s.rid.shape[0]
    loq = wp.empty(n, dtype=float, device=device)
    if smooth and p.smooth_radius > 0:
        tmp = wp.empty(n, dtype=float, device=device)
        for axis, src, dst in ((0, s.loq_raw, tmp), (1, tmp, loq)):
            launch_chunked(smooth_loq, n, inputs=[src, s.status, s.cam, gb.gpu(), p.smooth_radius, axis, p.depth_threshold],
                           outputs=[dst], device=device)
    else:
        wp.copy(loq, s.loq_raw)
    return SSMLoq(loq)


def run_visibility(setup: SSMSetup, maps: SSMMaps, gb, s: SSMSearch, loq: SSMLoq, samples: wp.array, device: str) -> tuple[wp.array, wp.array]:
    """Kernel 3: backprojection; (visibility, micro-occluders processed) per receiver."""
    n = s.rid.shape[0]
    vis = wp.empty(n, dtype=float, device=device)
    processed = wp.empty(n, dtype=wp.int32, device=device)
    mr = maps.microrects
    mr_ext = mr.ext if mr is not None else wp.empty(1, dtype=wp.vec4i, device=device)
    mr_dep = mr.dep if mr is not None else wp.empty(1, dtype=float, device=device)
    launch_chunked(
        backproject, n,
        inputs=[setup, maps.occluders.gpu, mr_ext, mr_dep, samples, gb.gpu(), s.rid, s.area, s.status, s.loq_raw, loq.loq],
        outputs=[vis, processed], device=device, min_chunk=64,
    )
    return vis, processed


def search_counters(s: SSMSearch, processed: wp.array | None = None) -> dict:
    status = s.status.numpy()
    covered = status != STATUS_BACKGROUND
    nc = max(int(covered.sum()), 1)
    pen = status == STATUS_PENUMBRA
    area = s.area.numpy()[pen] if pen.any() else np.zeros((0, 4), np.float32)
    widths = np.maximum(area[:, 2] - area[:, 0], area[:, 3] - area[:, 1]) if len(area) else np.zeros(0)
    out = {
        "receivers": int(covered.sum()),
        "samples": int(status.size),
        "backprojecting_fraction": float(pen.sum() / nc),
        "backprojecting_fraction_all_pixels": float(pen.sum() / max(status.size, 1)),
        "search_width_mean_texels": float(widths.mean()) if widths.size else 0.0,
        "umbra_fraction": float((status == STATUS_UMBRA).sum() / nc),
        "lit_fraction": float((status == STATUS_LIT).sum() / nc),
    }
    if processed is not None:
        cnt = processed.numpy()[pen].astype(np.float64)
        out["occluders_mean"] = float(cnt.mean()) if cnt.size else 0.0
        out["occluders_max"] = int(cnt.max()) if cnt.size else 0
        out["occluders_stdev"] = float(cnt.std()) if cnt.size else 0.0
        out["occluders_total"] = int(cnt.sum())
    return out


class SSM(Technique):
    """Backprojection soft shadow mapping: micro-occluders, bitmasks, HSM/MSSM/YSM, budgets, smooth LOQ, MSAA."""

    name = "ssm"
    distant_angle_limit = 110.0  # max point error 0.082 at 110 degrees, 0.134 at 120
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "backprojection soft shadow mapping (micropatches/microquads/microrects, area or bitmask, HSM/MSSM/YSM, budget, smooth LOQ, MSAA resolve)"
    Params = SSMParams
    passes = (
        PassSpec("structure", reads=("light_depth",), writes=("ssm_maps",)),
        PassSpec("search", reads=("gbuffer", "light_depth", "ssm_maps"), writes=("ssm_search",)),
        PassSpec("smooth", reads=("gbuffer", "light_depth", "ssm_search"), writes=("ssm_loq",)),
        PassSpec("backprojection", reads=("gbuffer", "light_depth", "ssm_maps", "ssm_search", "ssm_loq"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    quality = (Quality("budget", (4.0, 8.0, 16.0, math.inf), "b_mo, micro-occluders per axis: more is closer to level 0 and slower"),)
    tolerance = Tolerance(mae=0.0005, mae_penumbra=0.012)
    distance_refusal = "its pruning pyramids and merged micro-occluders classify receivers by depth ranges of all casters, not by each caster's distance"
    ellipsoid_caveat = "its bounding sphere (back-projection onto a disk of its largest semi-axis)"
    cylinder_model = ("backprojection onto its bound seen along the light view's axis (toward the receivers' mean, its x along the "
                      "cylinder): a rectangle of its projected length by its diameter, as a rect light (a line light: 1e-3 of its length wide)")

    def supports(self, scene, light) -> str | None:
        why = super().supports(scene, light)
        if why is not None:
            return why
        if light.kind == LIGHT_POINT or (light.kind == LIGHT_DISTANT and light.angle_deg <= 0.0) or light.extent() <= 0.0:
            return "the light has no area (a point light or a sun of angle 0): no soft shadow to backproject"
        return None

    def bake_support(self) -> str | None:
        # without a pixel grid the LOQ smoothing (§4.2) finds no neighbours: each point keeps its own level
        if self.params.budget_map:
            return f"budget_map={self.params.budget_map!r} gives b_mo per pixel of the image and a bake has no image; bake without it"
        return None

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        # the pruning structure and microrects depend on the map only: shared by every budget
        maps_key = ctx.shared_key("ssm_maps", light, p.shadow_map_size, "structure", "ysm_size", "occluder", "microrect_diagonal", "microrect_tie")
        search_key = ctx.key("ssm_search", light)
        loq_key = ctx.key("ssm_loq", light)
        out = ctx.visibility_key(light)
        dev = ctx.device
        disk = disk_shaped(light)
        budget = budget_image(p, ctx.width, ctx.height)
        pts, code = light_samples(p.pattern, p.bitmask_size, disk, p.seed, dev)
        counters = ctx.counters(light)

        def setup_of(dm) -> SSMSetup:
            st = SSMSetup()
            st.lv = dm.view.gpu()
            st.k = light_kernel(light, dm.view)
            st.occluder = OCCLUDERS[p.occluder]
            st.bitmask = int(p.visibility == "bitmask")
            st.n = p.bitmask_size
            st.pattern = code
            st.gap_fill = int(p.gap_fill)
            st.overprecision = int(p.overprecision)
            st.gather_extent = int(p.gather == "extent")
            st.refine = p.refine
            st.bias = p.bias * dm.view.extent
            st.blend = int(p.blend and bool(np.isfinite(budget).any()))
            return st

        def build(res):
            return {maps_key: build_maps(res[depth].depth, p, dev)}

        def search(res):
            gb, dm = res[gbuf], res[depth]
            return {search_key: run_search(setup_of(dm), res[maps_key], gb, p, budget, dev)}

        def smooth(res):
            st = setup_of(res[depth])
            return {loq_key: run_smoothing(res[search_key], res[gbuf], p, bool(st.blend), dev)}

        def visibility(res):
            gb, dm, s, maps, lq = res[gbuf], res[depth], res[search_key], res[maps_key], res[loq_key]
            vis_r, processed = run_visibility(setup_of(dm), maps, gb, s, lq, pts, dev)
            counters["structure_build_ms"] = round(maps.structure.build_ms, 3)
            if maps.microrects is not None:
                counters["microrect_build_ms"] = round(maps.microrects.build_ms, 3)
            counters["memory_bytes"] = {k2: int(a.size * wp.types.type_size_in_bytes(a.dtype)) for k2, a in maps.arrays().items()}
            counters.update(search_counters(s, processed))
            status = s.status.numpy()
            pen = status == STATUS_PENUMBRA
            loq = np.minimum(lq.loq.numpy(), np.log2(p.shadow_map_size))
            if setup_of(dm).blend:
                lo, frac = np.floor(loq[pen]).astype(int), loq[pen] - np.floor(loq[pen])
                used = np.concatenate([lo, (lo + 1)[frac > 1e-4]])
            else:
                used = np.ceil(s.loq_raw.numpy()[pen] - 1e-6).astype(int)
            hist = np.bincount(np.clip(used, 0, None), minlength=1) if used.size else np.zeros(1, int)
            counters["levels_used"] = {str(i): int(c) for i, c in enumerate(hist) if c}
            if s.layers == gb.spp:  # one receiver per sample
                vis = vis_r
            else:
                vis = msaa_resolve(vis_r, s.rid, gb, p.tau, p.msaa == "interpolate", dev)
            return {out: ctx.visibility(vis)}

        ctx.add_pass(str(maps_key), inputs=(depth,), outputs=(maps_key,), run=build, stage="structure", light=light)
        ctx.add_pass(ctx.pass_name("ssm_search", light), inputs=(gbuf, depth, maps_key), outputs=(search_key,), run=search, stage="search", light=light)
        ctx.add_pass(ctx.pass_name("ssm_smooth", light), inputs=(gbuf, depth, search_key), outputs=(loq_key,), run=smooth, stage="smooth", light=light)
        return ctx.add_pass(ctx.pass_name("ssm", light), inputs=(gbuf, depth, maps_key, search_key, loq_key), outputs=(out,), run=visibility,
                            stage="backprojection", light=light)


__all__ = ["SSM", "SSMParams"]
