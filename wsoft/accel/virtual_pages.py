"""Virtual shadow maps: a very large light depth map (``virtual_size`` texels a side, 16384 by
default) cut into square pages (``page_size`` texels, 128 by default), of which only the pages the
frame's receivers read are drawn, into a pool of physical pages (``pool_pages``), and kept from
frame to frame while they stay valid. The technique modules ``vsmap`` (a PCF lookup) and ``smrt``
(shadow-map ray tracing) read it; the page machinery lives here once.

Levels (:class:`VirtualLayout`):

* a **distant light** has clipmap levels around the camera: level ``k`` is a
  ``virtual_size``-texel orthographic map along the light whose window is ``first_extent * 2^k``
  world units wide, centred on the camera's position in light space and moved in whole pages (a
  page keeps its place in the world while the camera moves, so a cached page stays valid);
  ``first_extent`` 0 sizes level 0 so that the last level spans :data:`LAST_LEVEL_SPAN` times the
  scene's bounding diagonal (the whole scene from a camera anywhere near it, and texels coarse
  enough for the footprint of far pixels);
* a **local light** (rect, disk, a sphere seen in one frustum) has one perspective map from its
  centre over the window of its fitted light view (:meth:`~wsoft.pipeline.context.RenderContext.light_view`,
  squared), with mips: level ``k`` has ``virtual_size / 2^k`` texels a side, down to one page.

Texels of level ``k`` are ``2^k`` times as wide as level 0's (window units: world units for a
distant light, tangents for a local one). Page ``(gx, gy)`` of level ``k`` covers window
coordinates ``anchor + [gx, gx+1) x [gy, gy+1)`` times ``page_size * texel_k``; a level's map is
the square of ``pages`` pages from its ``corner``.

Per frame (:class:`VirtualPages`):

1. **Requests** (:func:`mark_pages`): each covered G-buffer sample picks the finest level whose
   texel is at least its pixel's footprint (``dist * pixel angle``, times ``2^lod_bias``) and that
   holds it, and marks the pages under a box of ``reach`` texels around it (a filter's or a ray's
   reach) at that level. Marking stores 1 (the same value from every writer: concurrent chunks
   cannot lose a mark).
2. **Overflow**: when more pages are requested than the pool holds, the finest level's pages are
   moved to their parents (one level coarser) until they fit; counter ``overflow_pages`` and one
   warning per light and frame. A lookup that finds no page at its level reads the next coarser
   level holding one: a coarser shadow, never a silent hole. A sample with no page at any level
   (outside the last clipmap level) is counted (``unmapped_samples``) and warned about.
3. **Cache**: a page already resident and valid is reused; the others are drawn into free
   physical pages or into those of pages nobody requested this frame, least recently used first
   (``evicted``). Every page is invalidated when the light, the levels' frame or the scene's
   bounds change; a page is invalidated when a dynamic caster (``Scene.tri_dynamic``) moved within
   it since the page was drawn (its light-space bounds before and after).
4. **Drawing**: the pages to draw are grouped into square tiles of up to ``TILE_PAGES`` pages a
   side, each tile a small view of the shared depth-map rasterizer
   (:func:`~wsoft.raster.depth_map.rasterize`: alpha-tested, the light's casters only), whose
   requested pages are copied into the pool (:func:`copy_pages`).

Counters (:meth:`VirtualPages.counters`): ``requested``, ``rendered``, ``reused``, ``evicted``,
``invalidated``, ``overflow_pages``, ``resident``, ``pool_pages``, ``dense_pages`` (pages of every
level's full map: what a dense map of every level would draw), ``tiles_drawn``.

On the device the map is a :class:`VirtualMapGPU`; :func:`virtual_depth` reads a texel through the
page table with the fallback to coarser levels, :func:`level_view` gives a level as a
:class:`~wsoft.lightspace.view.ViewGPU` (so the shared texel maths applies to it).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.errors import ParameterError
from wsoft.lightspace.fit import distant_axes
from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU, map_coords, to_frame, view_of
from wsoft.parallel import launch_chunked
from wsoft.raster.depth_map import rasterize
from wsoft.raster.gbuffer import GBufferGPU

TILE_PAGES = 8  # pages a side of one drawn tile (a 1024-texel view at 128-texel pages)
UNMAPPED = wp.constant(-1.0)  # virtual_depth: no page holds the texel at its level or any coarser one
LAST_LEVEL_SPAN = 16.0  # first_extent 0: the last clipmap level spans this many scene diagonals


@dataclass(frozen=True)
class VirtualConfig:
    """How a light's virtual map is laid out and stored (every field hashable; the techniques'
    parameters of the same names)."""

    virtual_size: int = 16384  # texels a side of each level's map (level 0 of a local light's mips)
    page_size: int = 128  # texels a side of a page
    pool_pages: int = 2048  # physical pages (each page_size^2 float32: 2048 x 64 KiB = 128 MiB)
    clip_levels: int = 16  # distant lights: clipmap levels
    first_extent: float = 0.0  # distant lights: world width of level 0's map (0: the last level spans LAST_LEVEL_SPAN scene diagonals)
    lod_bias: float = -1.0  # log2 of the texel size over the pixel footprint a sample asks for (negative: finer)
    footprint: float = 0.0  # > 0: every sample's footprint in world units (a bake, which has no camera); 0: its pixel's

    @property
    def pages(self) -> int:
        return self.virtual_size // self.page_size


@wp.struct
class VirtualMapGPU:
    """A virtual map on the device. ``view``: the light's frame (origin, axes, projection, depth
    range; its window and size are level 0's whole map); ``corner``: per level (first page x, first
    page y, pages a side); ``table``: ``[levels, pages, pages]`` flat int32, the physical page of
    each page of each level's map or -1; ``pool``: ``[pool_pages * page, page]`` float32 depths."""

    view: ViewGPU
    anchor: wp.vec2
    texel0: float
    page: int
    pages: int
    levels: int
    corner: wp.array[wp.vec3i]
    table: wp.array[wp.int32]
    pool: wp.array2d[float]


@wp.func
def level_texel(vm: VirtualMapGPU, k: int) -> float:
    """Level ``k``'s texel in window units."""
    return vm.texel0 * wp.pow(2.0, float(k))


@wp.func
def level_view(vm: VirtualMapGPU, k: int) -> ViewGPU:
    """Level ``k``'s whole map as a view: the light's frame with the level's window and size."""
    c = vm.corner[k]
    t = level_texel(vm, k)
    span = float(c[2] * vm.page) * t
    l = vm.anchor[0] + float(c[0] * vm.page) * t
    b = vm.anchor[1] + float(c[1] * vm.page) * t
    lv = vm.view
    lv.window = wp.vec4(l, l + span, b, b + span)
    lv.scale = wp.vec2(1.0 / t, 1.0 / t)
    lv.width = c[2] * vm.page
    lv.height = c[2] * vm.page
    return lv


@wp.func
def level_texel_coords(vm: VirtualMapGPU, k: int, m: wp.vec2) -> wp.vec2:
    """Continuous texel coordinates of window coordinates ``m`` in level ``k``'s map."""
    c = vm.corner[k]
    t = level_texel(vm, k)
    return wp.vec2((m[0] - vm.anchor[0]) / t - float(c[0] * vm.page), (m[1] - vm.anchor[1]) / t - float(c[1] * vm.page))


@wp.func
def level_holds(vm: VirtualMapGPU, k: int, m: wp.vec2, margin: float) -> bool:
    """Does level ``k``'s map hold window coordinates ``m`` with ``margin`` texels around them?"""
    t = level_texel_coords(vm, k, m)
    size = float(vm.corner[k][2] * vm.page)
    return t[0] >= margin and t[1] >= margin and t[0] < size - margin and t[1] < size - margin


@wp.func
def texel_depth(vm: VirtualMapGPU, k: int, tx: int, ty: int) -> float:
    """The stored depth of texel (tx, ty) of level ``k``'s map, or ``UNMAPPED`` (off the map, or no page there)."""
    n = vm.corner[k][2]
    px = tx / vm.page
    py = ty / vm.page
    if tx < 0 or ty < 0 or px >= n or py >= n:
        return UNMAPPED
    phys = vm.table[(k * vm.pages + py) * vm.pages + px]
    if phys < 0:
        return UNMAPPED
    return vm.pool[phys * vm.page + (ty - py * vm.page), tx - px * vm.page]


@wp.func
def virtual_depth(vm: VirtualMapGPU, k: int, m: wp.vec2) -> wp.vec2:
    """The stored depth at window coordinates ``m`` from level ``k``, or from the first coarser
    level holding a page there: (depth, level read), or (``UNMAPPED``, -1)."""
    for j in range(k, vm.levels):
        t = level_texel_coords(vm, j, m)
        d = texel_depth(vm, j, int(wp.floor(t[0])), int(wp.floor(t[1])))
        if d != UNMAPPED:
            return wp.vec2(d, float(j))
    return wp.vec2(UNMAPPED, -1.0)


@wp.func
def sample_level(vm: VirtualMapGPU, v: wp.vec3, footprint: float, reach: float) -> int:
    """The level a receiver (view-space ``v``) of pixel footprint ``footprint`` (world units) reads:
    the finest whose texel is at least the footprint in window units and whose map holds it with
    ``reach`` texels around it; -1 when none does (or a local light's receiver is behind it)."""
    w = footprint
    if vm.view.persp != 0:
        if v[2] <= vm.view.near:
            return -1
        w = footprint / v[2]
    k0 = int(wp.ceil(wp.log2(wp.max(w, 1.0e-30) / vm.texel0)))
    k0 = wp.clamp(k0, 0, vm.levels - 1)
    m = map_coords(vm.view, v)
    for k in range(k0, vm.levels):
        if level_holds(vm, k, m, reach):
            return k
    for k in range(k0, vm.levels):  # no level holds the whole reach: the first that holds the point
        if level_holds(vm, k, m, 0.0):
            return k
    return -1


@wp.func
def pixel_footprint(gb: GBufferGPU, i: int, per_distance: float, constant: float) -> float:
    """A sample's pixel footprint in world units (``per_distance`` x its camera distance + ``constant``)."""
    return per_distance * gb.dist[i] + constant


@wp.kernel
def mark_pages(
    offset: int,
    vm: VirtualMapGPU,
    gb: GBufferGPU,
    per_distance: float,
    constant: float,
    reach: float,
    # outputs
    requests: wp.array[wp.int32],
    level_of: wp.array[wp.int32],
):
    """Per covered sample: its level (``level_of``, -1: background or no level holds it, -2: outside a
    local light's view) and a 1 in
    ``requests`` (``[levels, pages, pages]``) for every page under ``reach`` texels around it."""
    i = wp.tid() + offset
    if gb.prim[i] < 0:
        level_of[i] = -1
        return
    v = view_of(vm.view, gb.pos[i])
    k = sample_level(vm, v, pixel_footprint(gb, i, per_distance, constant), reach)
    if k < 0 and vm.view.persp != 0:
        k = -2  # outside a local light's fitted view: its light view pass counts and warns about those it reaches
    level_of[i] = k
    if k < 0:
        return
    t = level_texel_coords(vm, k, map_coords(vm.view, v))
    n = vm.corner[k][2]
    x0 = wp.clamp(int(wp.floor(t[0] - reach)) / vm.page, 0, n - 1)
    x1 = wp.clamp(int(wp.floor(t[0] + reach)) / vm.page, 0, n - 1)
    y0 = wp.clamp(int(wp.floor(t[1] - reach)) / vm.page, 0, n - 1)
    y1 = wp.clamp(int(wp.floor(t[1] + reach)) / vm.page, 0, n - 1)
    if t[0] - reach < 0.0:
        x0 = 0
    if t[1] - reach < 0.0:
        y0 = 0
    for py in range(y0, y1 + 1):
        for px in range(x0, x1 + 1):
            requests[(k * vm.pages + py) * vm.pages + px] = 1  # the same value from every writer


@wp.kernel
def copy_pages(
    offset: int,
    src: wp.array2d[float],
    pages: wp.array[wp.vec3i],
    page: int,
    # outputs
    pool: wp.array2d[float],
):
    """Copy pages of a drawn tile into the pool: ``pages[q]`` = (page x, page y in the tile,
    physical page); one thread a texel; each physical page is written by its own threads only."""
    i = wp.tid() + offset
    q = i / (page * page)
    r = i - q * page * page
    y = r / page
    x = r - y * page
    e = pages[q]
    pool[e[2] * page + y, x] = src[e[1] * page + y, e[0] * page + x]


@dataclass
class VirtualLayout:
    """One frame's levels of a light's virtual map: the light's frame (``origin``, ``axes``,
    ``persp``, ``near``, ``far``), the page grid's ``anchor`` and level 0's ``texel0`` (window
    units), and per level its map's first page and size in pages (``corners``, [levels, 3] int).
    ``clipmap``: levels of equal size around the camera (distant) or mips (local)."""

    light_path: str
    persp: bool
    origin: np.ndarray
    axes: np.ndarray
    near: float
    far: float
    anchor: tuple[float, float]
    texel0: float
    corners: np.ndarray
    clipmap: bool
    extent: float

    def frame_key(self) -> tuple:
        """What a cached page's depths depend on besides the casters: the light's frame and the page grid."""
        return (self.persp, tuple(np.round(self.origin, 9)), tuple(np.round(self.axes.ravel(), 12)), self.near, self.far,
                self.anchor, self.texel0, self.clipmap)

    @property
    def levels(self) -> int:
        return len(self.corners)

    def tile_view(self, k: int, gx: int, gy: int, tiles: int, page: int) -> LightView:
        """The view of ``tiles`` x ``tiles`` pages of level ``k`` from global page (gx, gy)."""
        t = self.texel0 * 2.0 ** k
        l = self.anchor[0] + gx * page * t
        b = self.anchor[1] + gy * page * t
        span = tiles * page * t
        return LightView(light_path=self.light_path, persp=self.persp, origin=self.origin, axes=self.axes,
                         window=(l, l + span, b, b + span), near=self.near, far=self.far, width=tiles * page, height=tiles * page,
                         extent=self.extent)


def distant_layout(light, scene_lo: np.ndarray, scene_hi: np.ndarray, camera_pos: np.ndarray, cfg: VirtualConfig) -> VirtualLayout:
    """A distant light's clipmap: an orthographic frame along its emission whose origin lies before
    the scene's bounds (depths positive over the whole scene) and, across the light, on the
    coarsest level's page nearest ``camera_pos``; levels centred on the camera in whole pages."""
    axes = distant_axes(light)
    lo, hi = np.asarray(scene_lo, np.float64), np.asarray(scene_hi, np.float64)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo)) + 1e-6
    base = centre - axes[:, 2] * (radius * 1.01)
    diag = 2.0 * radius
    levels = int(cfg.clip_levels)
    first = cfg.first_extent if cfg.first_extent > 0 else LAST_LEVEL_SPAN * diag / 2.0 ** (levels - 1)
    texel0 = first / cfg.virtual_size
    # the frame's origin across the light near the camera, on the grid of the coarsest level's pages:
    # window coordinates stay small (float32 keeps level 0's texels apart) and move only when the
    # camera crosses such a page (every page is then drawn again)
    snap = cfg.page_size * texel0 * 2.0 ** (levels - 1)
    c0 = to_frame(np.asarray(camera_pos, np.float64)[None], base, axes, threads=False)[0]
    origin = base + axes[:, 0] * (round(c0[0] / snap) * snap) + axes[:, 1] * (round(c0[1] / snap) * snap)
    cam = to_frame(np.asarray(camera_pos, np.float64)[None], origin, axes, threads=False)[0]
    n = cfg.pages
    corners = np.zeros((levels, 3), np.int64)
    for k in range(levels):
        pw = cfg.page_size * texel0 * 2.0 ** k
        corners[k] = (int(round(cam[0] / pw)) - n // 2, int(round(cam[1] / pw)) - n // 2, n)
    return VirtualLayout(light.path, False, origin, axes, 0.0, radius * 2.03, (0.0, 0.0), texel0, corners, True, diag)


def local_layout(light, view: LightView, cfg: VirtualConfig) -> VirtualLayout:
    """A local light's mips over its fitted view's window (squared about its lower-left corner)."""
    l, r, b, t = view.window
    texel0 = max(r - l, t - b) / cfg.virtual_size
    n = cfg.pages
    levels = int(math.log2(n)) + 1
    corners = np.array([(0, 0, max(n >> k, 1)) for k in range(levels)], np.int64)
    return VirtualLayout(light.path, True, np.asarray(view.origin, np.float64), np.asarray(view.axes, np.float64), float(view.near),
                         float(view.far), (float(l), float(b)), texel0, corners, False, float(view.extent))


def _page_boxes(layout: VirtualLayout, page: int, lo_xy: np.ndarray, hi_xy: np.ndarray):
    """Per level, the global page ranges (x0, x1, y0, y1 inclusive) under window boxes [N, 2]."""
    out = []
    for k in range(layout.levels):
        pw = page * layout.texel0 * 2.0 ** k
        x0 = np.floor((lo_xy[:, 0] - layout.anchor[0]) / pw).astype(np.int64)
        x1 = np.floor((hi_xy[:, 0] - layout.anchor[0]) / pw).astype(np.int64)
        y0 = np.floor((lo_xy[:, 1] - layout.anchor[1]) / pw).astype(np.int64)
        y1 = np.floor((hi_xy[:, 1] - layout.anchor[1]) / pw).astype(np.int64)
        out.append((x0, x1, y0, y1))
    return out


def window_bounds(layout: VirtualLayout, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Window-space bounds (lo, hi: [N, 2]) of triangles given by their view-space corners ``v``
    [N, 3, 3]; a perspective frame's triangles reaching its near plane span everything."""
    if layout.persp:
        z = v[..., 2]
        ok = z.min(axis=1) > max(layout.near, 1e-12)
        zz = np.where(z > 1e-12, z, 1.0)
        x, y = v[..., 0] / zz, v[..., 1] / zz
        big = 1e30
        lo = np.stack([np.where(ok, x.min(axis=1), -big), np.where(ok, y.min(axis=1), -big)], axis=1)
        hi = np.stack([np.where(ok, x.max(axis=1), big), np.where(ok, y.max(axis=1), big)], axis=1)
        return lo, hi
    return v[..., :2].min(axis=1), v[..., :2].max(axis=1)


def window_boxes(layout: VirtualLayout, tri_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Window-space bounds of triangles ``tri_points`` [N, 3, 3] (world) in the layout's frame."""
    v = to_frame(tri_points.reshape(-1, 3), layout.origin, layout.axes, threads=False).reshape(-1, 3, 3)
    return window_bounds(layout, v)


class VirtualPages:
    """A light's virtual map across the frames of a sequence: the physical pool, the resident pages
    (``(level, gx, gy)`` -> physical page), their last use, and the counters of the last frame.
    Kept by the technique between frames (:meth:`~wsoft.pipeline.technique_context.TechniqueContext.keep`)."""

    def __init__(self, cfg: VirtualConfig, device: str):
        self.cfg = cfg
        self.device = device
        self.capacity = 0  # physical pages allocated so far (the pool grows up to pool_pages as pages are asked for)
        self.pool = wp.zeros((cfg.page_size, cfg.page_size), dtype=float, device=device)
        self.resident: dict[tuple[int, int, int], int] = {}
        self.last_used: dict[tuple[int, int, int], int] = {}
        self.free: list[int] = []
        self.frame_key: tuple | None = None
        self.dynamic_points: np.ndarray | None = None  # the dynamic casters' corners [N, 3, 3] when the pages were drawn
        self.frame = -1
        self.stats: dict = {}
        # the casters' window bounds of the last draw, kept while the device scene (rebuilt by
        # Scene.changed) and the frame stay and no dynamic caster moved
        self._boxes: tuple | None = None
        self._casters_still = False

    # -- invalidation ------------------------------------------------------------------------------
    def _drop(self, key) -> None:
        self.free.append(self.resident.pop(key))
        self.last_used.pop(key, None)

    def invalidate_all(self) -> int:
        n = len(self.resident)
        for key in list(self.resident):
            self._drop(key)
        return n

    def invalidate_boxes(self, layout: VirtualLayout, lo: np.ndarray, hi: np.ndarray) -> int:
        """Drop the resident pages under any of the window boxes (lo, hi: [N, 2]); how many."""
        if not self.resident or len(lo) == 0:
            return 0
        keys = np.array(list(self.resident), np.int64)  # [R, 3]
        hit = np.zeros(len(keys), bool)
        for k, (x0, x1, y0, y1) in enumerate(_page_boxes(layout, self.cfg.page_size, lo, hi)):
            sel = keys[:, 0] == k
            if not sel.any():
                continue
            kx, ky = keys[sel, 1][:, None], keys[sel, 2][:, None]
            hit[sel] = np.any((kx >= x0[None]) & (kx <= x1[None]) & (ky >= y0[None]) & (ky <= y1[None]), axis=1)
        for key in keys[hit]:
            self._drop(tuple(int(x) for x in key))
        return int(hit.sum())

    # -- one frame ---------------------------------------------------------------------------------
    def update(self, layout: VirtualLayout, requests: np.ndarray, ds, casters, dynamic: np.ndarray | None,
               alpha: bool) -> VirtualMapGPU:
        """Bring the pool up to date for one frame: ``requests`` ([levels, pages, pages] int, from
        :func:`mark_pages`); ``ds`` the device scene; ``casters`` the light's casting triangles as
        (points [V, 3], corner indices [T, 3], soup indices [T]): each tile draws those whose bounds
        reach it (None: an instanced scene, every caster drawn, instances culled by each tile's view);
        ``dynamic`` the dynamic casters' world corners [N, 3, 3] (None: none); returns the map for the
        lookups. Counters in :attr:`stats`."""
        cfg, P = self.cfg, self.cfg.page_size
        self.frame += 1
        st = {"requested": 0, "rendered": 0, "reused": 0, "evicted": 0, "invalidated": 0, "overflow_pages": 0,
              "pool_pages": cfg.pool_pages, "page_size": P, "levels": layout.levels, "tiles_drawn": 0,
              "dense_pages": int(sum(int(c[2]) ** 2 for c in layout.corners))}
        key = layout.frame_key()
        if key != self.frame_key:
            st["invalidated"] += self.invalidate_all()
            self.frame_key = key
            self.dynamic_points = None
        self._casters_still = dynamic is None or (self.dynamic_points is not None and self.dynamic_points.shape == dynamic.shape
                                                  and np.array_equal(self.dynamic_points, dynamic))
        if dynamic is not None and len(dynamic):
            if self.dynamic_points is not None and self.dynamic_points.shape == dynamic.shape:
                moved = np.any(self.dynamic_points != dynamic, axis=(1, 2))
                if moved.any():
                    lo0, hi0 = window_boxes(layout, self.dynamic_points[moved])
                    lo1, hi1 = window_boxes(layout, dynamic[moved])
                    st["invalidated"] += self.invalidate_boxes(layout, np.concatenate([lo0, lo1]), np.concatenate([hi0, hi1]))
            else:
                lo1, hi1 = window_boxes(layout, dynamic)
                if self.dynamic_points is not None:  # a different set of dynamic casters: every page they may touch
                    lo0, hi0 = window_boxes(layout, self.dynamic_points)
                    lo1, hi1 = np.concatenate([lo0, lo1]), np.concatenate([hi0, hi1])
                st["invalidated"] += self.invalidate_boxes(layout, lo1, hi1)
            self.dynamic_points = np.array(dynamic, copy=True)
        # requested pages as global keys
        want: set[tuple[int, int, int]] = set()
        req = requests.reshape(layout.levels, cfg.pages, cfg.pages)
        for k in range(layout.levels):
            ys, xs = np.nonzero(req[k])
            cx, cy = int(layout.corners[k][0]), int(layout.corners[k][1])
            want.update((k, int(x) + cx, int(y) + cy) for x, y in zip(xs, ys))
        st["requested"] = len(want)
        if len(want) > cfg.pool_pages:
            kept = self._demote(layout, want)
            st["overflow_pages"] = len(want - kept)  # requested pages read from a coarser level instead
            want = kept
        # reuse, then draw the rest
        reused = [w for w in want if w in self.resident]
        draw = sorted(w for w in want if w not in self.resident)
        st["reused"] = len(reused)
        for w in reused:
            self.last_used[w] = self.frame
        self._grow(len(draw) - len(self.free))
        need = len(draw) - len(self.free)
        if need > 0:
            victims = sorted((self.last_used.get(r, -1), r) for r in self.resident if r not in want)[:need]
            for _, r in victims:
                self._drop(r)
            st["evicted"] = len(victims)
        for w in draw:
            self.resident[w] = self.free.pop()
            self.last_used[w] = self.frame
        st["rendered"] = len(draw)
        st["tiles_drawn"] = self._draw(layout, draw, ds, casters, alpha)
        st["resident"] = len(self.resident)
        self.stats = st
        return self.gpu(layout)

    def _grow(self, more: int) -> None:
        """Allocate ``more`` physical pages (at least doubling, at most ``pool_pages`` in all), keeping the resident ones."""
        if more <= 0 or self.capacity >= self.cfg.pool_pages:
            return
        P = self.cfg.page_size
        new = min(self.cfg.pool_pages, max(self.capacity + more, 2 * self.capacity, 16))
        pool = wp.empty((new * P, P), dtype=float, device=self.device)
        if self.capacity:
            wp.copy(pool, self.pool, count=self.capacity * P * P)
        self.free.extend(range(new - 1, self.capacity - 1, -1))
        self.pool, self.capacity = pool, new

    def _demote(self, layout: VirtualLayout, want: set) -> set:
        """Move the finest level's requests to their parents (one level coarser) until they fit the pool."""
        want = set(want)
        while len(want) > self.cfg.pool_pages:
            finest = min(w[0] for w in want)
            if finest >= layout.levels - 1:
                break
            for w in sorted(w for w in want if w[0] == finest):
                want.discard(w)
                parent = (finest + 1, w[1] // 2, w[2] // 2)  # clipmap and mips alike: the page grid halves
                c = layout.corners[finest + 1]
                if c[0] <= parent[1] < c[0] + c[2] and c[1] <= parent[2] < c[1] + c[2]:
                    want.add(parent)
                if len(want) <= self.cfg.pool_pages:
                    break
        if len(want) > self.cfg.pool_pages:  # even the coarsest level's requests overflow
            raise ParameterError(f"pool_pages={self.cfg.pool_pages} cannot hold the {len(want)} pages the coarsest virtual-map level "
                                 f"needs; raise pool_pages or page_size")
        return want

    def _draw(self, layout: VirtualLayout, draw: list, ds, casters, alpha: bool) -> int:
        """Rasterize the pages ``draw`` tile by tile (each tile the casters whose window bounds reach
        it) and copy them into their physical pages."""
        P = self.cfg.page_size
        tiles: dict[tuple[int, int, int], list] = {}
        for w in draw:
            k, gx, gy = w
            c = layout.corners[k]
            tp = min(TILE_PAGES, int(c[2]))
            tx = c[0] + ((gx - c[0]) // tp) * tp  # tiles aligned on the level's map
            ty = c[1] + ((gy - c[1]) // tp) * tp
            tiles.setdefault((k, int(tx), int(ty)), []).append(w)
        if not tiles:
            return 0
        boxes = None
        if casters is not None:
            pts, tri, ids = casters
            key = (layout.frame_key(), len(ids))
            if self._boxes is not None and self._boxes[0] == key and self._boxes[1]() is ds and self._casters_still:
                boxes = self._boxes[2]  # the same device scene, frame and casters: the bounds of the last draw
            else:
                v = to_frame(np.asarray(pts), layout.origin, layout.axes)
                boxes = window_bounds(layout, v[np.asarray(tri)])
                self._boxes = (key, weakref.ref(ds), boxes)
        for (k, tx, ty), ws in sorted(tiles.items()):
            tp = min(TILE_PAGES, int(layout.corners[k][2]))
            xs = [w[1] - tx for w in ws]
            ys = [w[2] - ty for w in ws]
            x0, y0 = min(xs), min(ys)  # the smallest square of the tile's pages holding its requests
            side = min(max(max(xs) - x0, max(ys) - y0) + 1, tp)
            view = layout.tile_view(k, tx + x0, ty + y0, side, P)
            if boxes is None:
                depth = rasterize(ds, view, alpha_tested=alpha).depth
            else:
                l, r, b, t = view.window
                lo, hi = boxes
                sel = ids[(hi[:, 0] >= l) & (lo[:, 0] <= r) & (hi[:, 1] >= b) & (lo[:, 1] <= t)]
                if len(sel):
                    depth = rasterize(ds, view, alpha_tested=alpha, triangles=sel).depth
                else:
                    depth = wp.full((side * P, side * P), DEPTH_CLEAR, dtype=float, device=self.device)
            entries = np.array([(w[1] - tx - x0, w[2] - ty - y0, self.resident[w]) for w in ws], np.int32)
            pages = wp.array(entries, dtype=wp.vec3i, device=self.device)
            launch_chunked(copy_pages, len(ws) * P * P, inputs=[depth, pages, P], outputs=[self.pool], device=self.device,
                           min_chunk=1 << 14)
        return len(tiles)

    def gpu(self, layout: VirtualLayout) -> VirtualMapGPU:
        """The page table of the resident pages within each level's current map, and the map's frame."""
        cfg = self.cfg
        n = cfg.pages
        table = np.full((layout.levels, n, n), -1, np.int32)
        for (k, gx, gy), phys in self.resident.items():
            if k >= layout.levels:
                continue
            c = layout.corners[k]
            lx, ly = gx - c[0], gy - c[1]
            if 0 <= lx < c[2] and 0 <= ly < c[2]:
                table[k, ly, lx] = phys
        return make_gpu(layout, cfg, table, self.pool, self.device)


def make_gpu(layout: VirtualLayout, cfg: VirtualConfig, table: np.ndarray | None, pool, device: str) -> VirtualMapGPU:
    """A :class:`VirtualMapGPU` of ``layout`` (``table`` None: every page -1, for the request pass)."""
    vm = VirtualMapGPU()
    span = cfg.virtual_size * layout.texel0
    base = layout.tile_view(0, int(layout.corners[0][0]), int(layout.corners[0][1]), 1, cfg.page_size)
    base.window = (base.window[0], base.window[0] + span, base.window[2], base.window[2] + span)
    base.width = base.height = cfg.virtual_size
    vm.view = base.gpu()
    vm.anchor = wp.vec2(*layout.anchor)
    vm.texel0 = float(layout.texel0)
    vm.page = int(cfg.page_size)
    vm.pages = int(cfg.pages)
    vm.levels = int(layout.levels)
    vm.corner = wp.array(layout.corners.astype(np.int32), dtype=wp.vec3i, device=device)
    if table is None:
        table = np.full((layout.levels, cfg.pages, cfg.pages), -1, np.int32)
    vm.table = wp.array(table.reshape(-1), dtype=wp.int32, device=device)
    vm.pool = pool
    return vm


def request_pages(layout: VirtualLayout, cfg: VirtualConfig, gb, camera, height: int, reach: float, device: str):
    """Mark the pages the G-buffer's samples need (:func:`mark_pages`): (requests [levels, pages,
    pages] int32 numpy, level per sample [N] int32 numpy)."""
    per_distance, constant = footprint_terms(camera, height, cfg.lod_bias, cfg.footprint)
    vm = make_gpu(layout, cfg, None, wp.zeros((cfg.page_size, cfg.page_size), dtype=float, device=device), device)
    req = wp.zeros(layout.levels * cfg.pages * cfg.pages, dtype=wp.int32, device=device)
    level_of = wp.empty(gb.count, dtype=wp.int32, device=device)
    launch_chunked(mark_pages, gb.count, inputs=[vm, gb.gpu(), per_distance, constant, float(reach)], outputs=[req, level_of],
                   device=device, min_chunk=1024)
    return req.numpy(), level_of.numpy()


def footprint_terms(camera, height: int, lod_bias: float, footprint: float = 0.0) -> tuple[float, float]:
    """A pixel's footprint in world units as ``a * distance + b`` for ``camera`` at ``height``
    pixels, times ``2^lod_bias``: a perspective camera's pixel angle, an orthographic one's pixel;
    ``footprint`` > 0: that, for every sample (no camera needed)."""
    s = 2.0 ** float(lod_bias)
    if footprint > 0.0:
        return 0.0, s * float(footprint)
    if camera is None:
        raise ParameterError("a virtual map without a camera (a bake) needs footprint > 0: the world size its samples ask texels for")
    if camera.orthographic:
        return 0.0, s * 2.0 * float(camera.tan_half[1]) / height
    return s * 2.0 * float(camera.tan_half[1]) / height, 0.0


def light_casters(scene, light):
    """The light's casting triangles as :meth:`VirtualPages.update` takes them: (points, corner
    indices [T, 3], soup indices [T]); None for an instanced scene (every caster drawn)."""
    if scene.instanced:
        return None
    ids = scene.casting_triangles(light)
    tris = np.asarray(scene.triangles).reshape(-1, 3)
    if ids is None:
        ids = np.arange(len(tris), dtype=np.int32)
    return scene.points, tris[ids], np.asarray(ids, np.int32)


def dynamic_corners(scene, light) -> np.ndarray | None:
    """The world corners [N, 3, 3] of the dynamic casters (``Scene.tri_dynamic``) that cast
    ``light``'s shadow, or None when there are none."""
    dyn = scene.tri_dynamic
    if dyn is None or not np.any(dyn):
        return None
    mask = np.asarray(dyn, bool).copy()
    casting = scene.casting_mask(light)
    if casting is not None:
        mask &= np.asarray(casting, bool)[: len(mask)]
    if not mask.any():
        return None
    tris = np.asarray(scene.triangles)[mask]
    return np.asarray(scene.points, np.float64)[tris]
