"""Stable light views (:func:`fit_stable_view`): views whose texel size and texel grid stay put while
the camera turns or moves a little, so a shadow edge falls on the same texels frame after frame
and does not shimmer (the ``view=stable`` option of the shadow-map techniques,
:class:`~wsoft.params.LightViewParams`).

Three quantities are quantised, each to a grid fixed by the light and the world, not by the
receivers:

* **Size on a ladder.** A window's extent is rounded *up* to the next rung of :func:`ladder_up`,
  the powers of 2^(1/4) in world units (tangents for a perspective view): the texel size changes
  only when the receivers' extent crosses a rung, at most 19 % coarser than a tight fit (9 % on
  average). The rungs are absolute: any unit taken from the scene (its bounds' diagonal) moves with
  a moving caster and would move every rung, and powers of 2^(1/4) scale with the scene by any
  power of two.
* **Window origin on whole texels.** A distant light's window is the square around the bounding
  sphere of the fitted region (the receivers' bounds, grown for soft casters), its centre snapped
  to whole texels of a light-space grid anchored at the world origin (``anchor``: the world origin
  in the frame's coordinates, which a render far from the origin moves). A local light's window is
  centred on its axis's tangents, each axis's extent on the ladder, its centre on whole texels
  from the axis.
* **Depth range on a grid.** Near and far are snapped outward to multiples of an eighth of the
  depth span rounded up on the ladder (a distant light's from the anchor), so a sliding depth range
  does not change the normalised depths and biases frame to frame.

The axes are the light's alone: a distant light's and a rect or disk light's own frame; a sphere,
point or cylinder light looks at the mean of the receivers of a whole sequence when the renderer gives them
(``region``, as a fitted view looks at the mean of the frame's), else straight down the stage's
up axis (``down``): a lamp lights what lies below it, and a fixed downward axis is what a fitted
view of a lamp over its floor approaches. The centre of the scene's bounds would be a poorer
choice: a lamp near one side of a wide scene would look at it askew, and receivers right below
the lamp would fall beyond the ±80° window.

``region`` (world points [N, 3], the receivers of every frame of a sequence,
:attr:`~wsoft.pipeline.context.RenderContext.fit_receivers`) is fitted together with the frame's
receivers: a view fitted once per sequence, which still holds every receiver of the frame.
"""

from __future__ import annotations

import math

import numpy as np

from wsoft.lightspace.fit import (
    _caster_growth, _far_light_depths, _fit_points, _frame_bounds, _local_fit_stats, distant_axes, distant_caster_depth,
    local_axes, local_near, omni_axes, receiver_bounds,
)
from wsoft.lightspace.view import MAX_TAN, LightView, far_light, frame_extent_of_bounds, to_frame
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISTANT, LIGHT_POINT, LIGHT_SPHERE, Light

LADDER_STEPS = 4  # rungs of the size ladder per doubling
DEPTH_STEPS = 8  # a depth range is snapped to multiples of its span (on the ladder) over this


def ladder_up(x: float) -> float:
    """The smallest power of 2^(1/:data:`LADDER_STEPS`) at or above ``x`` (> 0); a rung (to within
    rounding) is its own."""
    k = math.ceil(LADDER_STEPS * math.log2(x) - 1e-9)
    while 2.0 ** (k / LADDER_STEPS) < x:
        k += 1
    return 2.0 ** (k / LADDER_STEPS)


def ladder_down(x: float) -> float:
    """The largest power of 2^(1/:data:`LADDER_STEPS`) at or below ``x`` (> 0); a rung (to within
    rounding) is its own."""
    k = math.floor(LADDER_STEPS * math.log2(x) + 1e-9)
    while 2.0 ** (k / LADDER_STEPS) > x:
        k -= 1
    return 2.0 ** (k / LADDER_STEPS)


def snapped_depths(z0: float, z1: float) -> tuple[float, float, float]:
    """``(z0', z1', step)``: ``z0' <= z0`` and ``z1' >= z1`` on multiples of ``step``, an eighth
    (:data:`DEPTH_STEPS`) of the span ``z1 - z0`` rounded up on the ladder."""
    step = ladder_up(max(z1 - z0, 1e-30)) / DEPTH_STEPS
    return math.floor(z0 / step) * step, math.ceil(z1 / step) * step, step


def snapped_window(lo: float, hi: float, size: int, margin_texels: float, limit: float = math.inf) -> tuple[float, float, float, int]:
    """One axis of a stable window: ``(l, r, texel, i)``. The extent ``hi - lo`` (at most
    ``2 limit``) rounded up on the ladder spans ``size - 2 margin_texels`` texels; the window is
    ``size`` texels centred ``i`` whole texels from 0 (the nearest to the middle of ``lo, hi``),
    moved inward by whole texels where it would reach past ``limit`` plus the border."""
    span = min(ladder_up(max(hi - lo, 1e-30)), 2.0 * limit)
    texel = span / max(size - 2.0 * margin_texels, 1.0)
    half = 0.5 * size * texel
    i = round(0.5 * (lo + hi) / texel)
    if math.isfinite(limit):
        room = max(math.floor((limit + margin_texels * texel - half) / texel + 1e-9), 0)
        i = min(max(i, -room), room)
    return i * texel - half, i * texel + half, texel, int(i)


def fit_stable_view(
    light: Light,
    receivers: np.ndarray,
    scene_lo: np.ndarray,
    scene_hi: np.ndarray,
    size: int,
    margin: float = 0.0,
    margin_texels: float = 1.0,
    casters: np.ndarray | None = None,
    all_casters=None,
    side_growth: tuple[float, float, float, float] | None = None,
    anchor: np.ndarray | None = None,
    region: np.ndarray | None = None,
    down: np.ndarray | None = None,
    caster_triangles=None,
) -> LightView:
    """A stable view of ``light`` (module docstring) holding ``receivers`` (world points [N, 3], the
    camera's visible surface) and ``region`` (more world points, e.g. a sequence's receivers; None:
    none). ``anchor``: the world origin in the frame's coordinates (None: the frame's origin), where
    a distant light's texel grid is anchored; ``down``: the stage's downward direction, a sphere,
    point or cylinder light's axis without ``region`` (None: the light's −Z axis). The other arguments are
    :func:`~wsoft.lightspace.fit.fit_light_view`'s, with the same meaning, and so are the counts:
    ``receivers_outside`` and ``receivers_behind`` count the frame's receivers alone. The view's
    ``snap`` holds what was quantised (``radius``, ``texel``, ``snap_offset``, ``depth_step``)."""
    if not 256 <= size <= 8192:
        from wsoft.errors import ParameterError

        raise ParameterError(f"shadow_map_size {size} out of range [256, 8192]")
    rec = np.asarray(receivers).reshape(-1, 3)
    if len(rec) == 0:
        rec = np.stack([scene_lo, scene_hi])
    both = rec if region is None or len(region) == 0 else np.concatenate([rec, np.asarray(region, rec.dtype).reshape(-1, 3)])
    pts = _fit_points(both)
    rlo, rhi, _ = receiver_bounds(pts)
    ext = ladder_up(frame_extent_of_bounds(rlo, rhi, light))
    anchor = np.zeros(3) if anchor is None else np.asarray(anchor, np.float64)
    if light.kind == LIGHT_DISTANT:
        return _stable_distant(light, both, rlo, rhi, scene_lo, scene_hi, size, margin, margin_texels, casters, anchor, ext,
                               caster_triangles)
    has_region = region is not None and len(region) > 0
    if light.kind in (LIGHT_SPHERE, LIGHT_POINT, LIGHT_CYLINDER):
        d = np.asarray(region, np.float64).reshape(-1, 3).mean(axis=0) - light.position if has_region else down
        if d is None or not np.linalg.norm(d) > 1e-9 * ext:
            d = -light.frame[:, 2]
        axes = omni_axes(light, np.asarray(d, np.float64))
    else:
        axes = local_axes(light)
    return _stable_local(light, axes, rec, pts, rlo, rhi, size, margin, margin_texels, casters, all_casters, side_growth, has_region, ext)


def _stable_distant(light, both, rlo, rhi, scene_lo, scene_hi, size, margin, margin_texels, casters, anchor, ext,
                    caster_triangles=None) -> LightView:
    """A distant light's stable view: the square around the fitted region's bounding sphere (grown
    for soft casters, radius on the ladder), its centre on whole texels from ``anchor``, its depth
    range from the nearest caster in the window's prism to the farthest receiver, snapped."""
    axes = distant_axes(light)
    centre = 0.5 * (rlo + rhi)
    vc = to_frame(centre[None], anchor, axes, threads=False)[0]
    half = 0.5 * float(np.linalg.norm(rhi - rlo)) + margin + 1e-4 * ext
    vlo, vhi = _frame_bounds(both, anchor, axes)
    zr_min, zr_max = float(vlo[2]), float(vhi[2])
    corners = np.array([[x, y, z] for x in (scene_lo[0], scene_hi[0]) for y in (scene_lo[1], scene_hi[1]) for z in (scene_lo[2], scene_hi[2])])
    pts = casters if casters is not None else corners
    vp = to_frame(np.asarray(pts).reshape(-1, 3), anchor, axes) if pts is not None and len(pts) else None

    def square(h):
        return vc[0] - h, vc[0] + h, vc[1] - h, vc[1] + h

    tan_a = math.tan(math.radians(0.5 * light.angle_deg)) if casters is not None and light.angle_deg > 0 else 0.0
    mesh = caster_triangles() if caster_triangles is not None else None
    zc = distant_caster_depth(vp, square(half), zr_min, zr_max, tan_a, mesh, anchor, axes)
    g = tan_a * max(zr_max - zc, 0.0)
    radius = ladder_up(half + g)
    l, r, tx, ix = snapped_window(vc[0] - radius, vc[0] + radius, size, margin_texels)
    b, t, ty, iy = snapped_window(vc[1] - radius, vc[1] + radius, size, margin_texels)
    # the whole window's prism: its nearer casters keep positive depths
    zc = min(zc, distant_caster_depth(vp, (l, r, b, t), zr_min, math.inf, 0.0, mesh, anchor, axes))
    lead = 1e-3 * ext
    z0, z1, step = snapped_depths(zc - lead, zr_max + lead)
    cx, cy = 0.5 * (l + r), 0.5 * (b + t)
    origin = anchor + axes @ np.array([cx, cy, z0])
    hw = 0.5 * (r - l)
    snap = {"radius": radius, "texel": tx, "snap_offset": [ix, iy], "depth_step": step}
    return LightView(light_path=light.path, persp=False, origin=origin, axes=axes, window=(-hw, hw, -hw, hw), near=0.0, far=float(z1 - z0),
                     width=size, height=size, receivers_outside=0, receivers_behind=0, extent=ext, growth=float(g), snap=snap)


def _stable_local(light, axes, rec, pts, rlo, rhi, size, margin, margin_texels, casters, all_casters, side_growth, has_region,
                  ext) -> LightView:
    """A local light's stable view along ``axes`` (module docstring): each axis's tangent extent on
    the ladder with its centre on whole texels from the axis, clamped to ±80° as
    :func:`~wsoft.lightspace.fit.fit_light_view`'s; near and far snapped."""
    origin = np.asarray(light.position, np.float64)
    zmin_ok = 1e-6 * ext
    one_sided = light.one_sided
    facing = np.asarray(light.frame, np.float64)[:, 2] if one_sided else None
    st = _local_fit_stats(pts, origin, axes, facing, zmin_ok, margin)
    s = st["front"] if one_sided and st["front"]["n"] else st["all"]
    own = _local_fit_stats(_fit_points(rec), origin, axes, facing, zmin_ok, margin) if has_region else st  # the frame's counts
    own_s = own["front"] if one_sided and own["front"]["n"] else own["all"]
    l, r, b, t = (s["l"], s["r"], s["b"], s["t"]) if s["n"] else (-1.0, 1.0, -1.0, 1.0)
    w = light.extent()
    growth = 0.0
    if casters is not None and w > 0 and s["n"]:
        g = _caster_growth(np.asarray(casters).reshape(-1, 3), origin, axes, (l, r, b, t), w, 1e-3 * ext, s["zmax"])
        if g is not None:
            growth = ladder_up(g)
            l, r, b, t = l - growth, r + growth, b - growth, t + growth
        if side_growth is not None:  # per side (l, r, b, t): casters beyond that edge found in a depth map
            more = [max(x - growth, 0.0) for x in side_growth]
            l, r, b, t = l - more[0], r + more[1], b - more[2], t + more[3]
    l, r = max(l, -MAX_TAN), min(r, MAX_TAN)
    b, t = max(b, -MAX_TAN), min(t, MAX_TAN)
    l, r, tx, ix = snapped_window(l, r, size, margin_texels, MAX_TAN)
    b, t, ty, iy = snapped_window(b, t, size, margin_texels, MAX_TAN)
    near, nearest = local_near(ext, s["zmin"] if s["n"] else None, all_casters, origin, axes)
    far = (s["zmax"] if s["n"] else ext) * 1.01 + 1e-3 * ext
    step = None
    if s["n"] and all_casters is not None and far_light(light, rlo, rhi):
        near, far = _far_light_depths(all_casters(), origin, axes, s["zmin"], s["zmax"], near, ext)
        near_q, far, step = snapped_depths(near, far)
        near = near_q if near_q > 0.0 else ladder_down(near)
    else:
        near, far = ladder_down(near), ladder_up(far)
    inner = 0.5 * (size - 2.0 * margin_texels)  # texels from the window's centre to its border
    snap = {"radius": [inner * tx, inner * ty], "texel": [tx, ty], "snap_offset": [ix, iy]}
    if step is not None:
        snap["depth_step"] = step
    return LightView(light_path=light.path, persp=True, origin=origin, axes=axes, window=(l, r, b, t), near=float(near), far=float(far),
                     width=size, height=size, receivers_outside=own_s["outside"], receivers_behind=own["behind"], extent=ext,
                     growth=float(growth), snap=snap, nearest_caster=nearest)
