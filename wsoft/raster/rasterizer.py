"""The rasterizer: one scan conversion of triangles into a view, many fragment actions.

:func:`make_rasterizer` builds a :class:`Rasterizer` for a projection (perspective or
orthographic), a *fragment* and two modes, specialised at code generation (``wp.static``, as
warp.fem builds its kernels): nothing unused is compiled in.

* **Fragment** — a ``@wp.func`` made with :func:`fragment`, called for every texel (or pixel)
  a triangle covers: ``f(target, x, y, z, bary, tri)`` with the target struct (its first
  argument's type, e.g. :class:`~wsoft.raster.depth_map.DepthTarget`), the texel, the
  interpolated linear view depth, the perspective-correct weights of the triangle's corners at the texel (zeros unless the
  fragment asks for them) and the triangle's index. A fragment may write only what belongs to
  its texel (the texel itself, or what is bucketed under it): that is what lets the scheduler
  share the map out by bands of rows. A depth map keeps the nearest depth per texel
  (:mod:`wsoft.raster.depth_map`); an irregular z-buffer tests the eye samples of a cell
  (:mod:`wsoft.accel.izb_grid`); a shadow volume could OR bits into a pixel's mask.
* **conservative** — every texel a triangle touches (and those within
  :data:`~wsoft.raster.triangle.CONSERVATIVE_MARGIN` of a texel's edge, so that rounding never drops one), with the
  nearest depth over the texel (clamped to the triangle's range), instead of the texel centres it
  covers. **inner** (with conservative) is its opposite: only texels the triangle covers whole
  (within the same margin), with the *farthest* depth over the texel, and never a cutout triangle
  (its holes may let light through): a map of depths that certainly block every ray of the texel.
* **alpha** — triangles with a cutout material are alpha-tested per texel (perspective-correct
  uv at the texel centre).

Every kernel projects (a whole mesh's points once each first, :func:`project_points`: a mesh has
about half as many points as triangles), culls the far faces of closed surfaces (exact, from
:class:`~wsoft.scene.surfaces.Surfaces`), clips at a perspective view's near plane (one or two
triangles) and scan-converts (:mod:`wsoft.raster.triangle`: small boxes in one flat loop,
branch-free for a *masked* fragment in an orthographic view; wide triangles along exact spans of
covered texel centres). Fragments deeper than the view's far depth (behind every receiver: they
can shadow nothing) are not emitted, so a huge or far triangle cannot flood a map with depths
that wreck its depth range. Scheduling (:meth:`Rasterizer.run`):

* **CUDA**: one launch over (bands of :data:`GPU_BAND_ROWS` rows) x triangles; fragments write
  with real atomics.
* **CPU**: Warp runs a launch on one thread and its atomics are plain read-modify-write, so no
  two concurrent launches may touch the same element. A fragment that can *merge* (its target
  has an order-independent combine, :class:`FragmentSpec`): each worker rasterizes interleaved
  chunks of triangles into a private target, the private targets are merged by disjoint ranges,
  then triangles larger than
  :data:`BIG_TRIANGLE_TEXELS` (a ground plane) or crossing the near plane go to a second pass
  split into disjoint bands of rows. Any other fragment runs in disjoint bands of rows only.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import warp as wp

from wsoft.lightspace.view import LightView, ViewGPU, texel_of, view_of
from wsoft.parallel import cpu_threads, ensure_loaded, launch_chunked, run_tasks
from wsoft.raster.triangle import clip_point, make_raster_triangle
from wsoft.scene.surfaces import CULL_SKIP, Surfaces

GPU_BAND_ROWS = 64  # CUDA: rows per band (one thread per triangle and band)
CPU_CHUNK = 32768  # CPU: triangles per launch; a worker's chunks are interleaved with the others'
BIG_TRIANGLE_TEXELS = 4096  # CPU: triangles with a larger texel bounding box go to the banded pass
PRIVATE_BUDGET = 1 << 30  # CPU: bytes allowed for per-worker private targets
PERSPECTIVE = "perspective"
ORTHOGRAPHIC = "orthographic"




# --------------------------------------------------------------------------- fragments


@dataclass(frozen=True, eq=False)
class FragmentSpec:
    """What the scheduler knows of a fragment besides its code.

    ``private(target, device)`` makes a worker's private target (its writable arrays not yet
    cleared) and ``clear(private, device)`` clears it to the combine's identity; ``merge(privates,
    target, device)`` folds private targets into ``target`` by disjoint ranges. Without them
    (``None``) the fragment runs in disjoint bands of rows only. ``bary``: the fragment reads the
    corner weights (computed only then). ``masked``: a call with depth ``DEPTH_CLEAR`` changes
    nothing (a depth minimum), so a small triangle's flat loop calls it at every texel of its box,
    at ``DEPTH_CLEAR`` where the triangle does not cover the texel, without a branch per texel."""

    func: object
    target: type
    private: Callable | None = None
    clear: Callable | None = None
    merge: Callable | None = None
    bary: bool = False
    masked: bool = False

    @property
    def name(self) -> str:
        return self.func.key


FRAGMENTS: dict[str, FragmentSpec] = {}


def fragment(target: type, *, private=None, clear=None, merge=None, bary: bool = False, masked: bool = False):
    """Decorator: a ``@wp.func`` fragment ``f(target, x, y, z, bary, tri)`` registered with its
    :class:`FragmentSpec` (see :data:`FRAGMENTS`)."""

    def deco(f):
        func = wp.func(f)
        FRAGMENTS[func.key] = FragmentSpec(func, target, private, clear, merge, bary, masked)
        return func

    return deco


@wp.struct
class InstanceBatch:
    """The instances of one prototype, for an instanced run (:meth:`Rasterizer.run`): work item
    ``k`` is triangle ``k % ntri`` of the prototype (``points`` / ``indices`` then hold the
    prototypes', :class:`~wsoft.scene.instancing.DeviceInstances`) placed by instance ``k // ntri``."""

    to_world: wp.array[wp.mat44]  # [n] the instances' transforms
    cull_off: wp.array[wp.int32]  # [n] 1: keep every face of this instance (the view's origin is in its bounds)
    mirrored: wp.array[wp.int32]  # [n] 1: its winding flips (closed faces' outward side is the other one)
    ntri: int  # the prototype's triangles
    first: int  # its first triangle in ``indices``
    tri0: int  # its first triangle's combined index (cutouts, cull flags, the fragment's ``tri``)


@wp.kernel
def project_points(
    offset: int,
    points: wp.array[wp.vec3],
    lv: ViewGPU,
    # outputs
    proj: wp.array[wp.vec3],
):
    """Each point's texel coordinates (x, y; zeros for a perspective view's points before its near
    plane, which only clipped triangles have) and view depth (z), as the triangle kernel computes them."""
    i = wp.tid() + offset
    v = view_of(lv, points[i])
    t = wp.vec2(0.0)
    if lv.persp == 0 or v[2] >= lv.near:
        t = texel_of(lv, v)
    proj[i] = wp.vec3(t[0], t[1], v[2])


def _make_kernel(persp: bool, spec: FragmentSpec, conservative: bool, alpha: bool, listed: bool, defer_big: bool, inner: bool = False,
                 instanced: bool = False, preproj: bool = False):
    """One thread per (band of rows, triangle): project, cull, clip at the near plane, scan-convert.
    ``instanced``: work items are (instance, prototype triangle) pairs of an :class:`InstanceBatch`.
    ``preproj``: the points' texel coordinates and depths come from ``proj`` (:func:`project_points`,
    once per point rather than once per corner; a mesh has about half as many points as triangles)."""
    Target = spec.target
    raster_triangle = make_raster_triangle(persp, spec, conservative, alpha, inner)

    def rasterize_triangles(
        offset: int,
        band_start: int,
        band_rows: int,
        tri_list: wp.array[wp.int32],
        big_texels: float,
        points: wp.array[wp.vec3],
        indices: wp.array[wp.int32],
        lv: ViewGPU,
        cut: Surfaces,
        batch: InstanceBatch,
        proj: wp.array[wp.vec3],
        # outputs
        target: Target,
        big: wp.array[wp.int32],
    ):
        # listed: triangles are tri_list[t + offset]; defer_big: triangles whose texel bounding box
        # exceeds big_texels (or that cross the near plane) are only flagged in big, for a banded pass
        bi, t = wp.tid()
        band = bi + band_start
        item = t + offset
        if wp.static(listed):
            item = tri_list[item]
        row0 = band * band_rows
        row1 = wp.min(row0 + band_rows, lv.height)
        tri = item  # the combined triangle index
        cull = int(0)
        pa = wp.vec3(0.0)
        pb = wp.vec3(0.0)
        pc = wp.vec3(0.0)
        ia = int(0)
        ib = int(0)
        ic = int(0)
        if wp.static(instanced):
            i = item // batch.ntri
            k = item - i * batch.ntri
            tri = batch.tri0 + k
            m = batch.to_world[i]
            g = batch.first + k
            pa = wp.transform_point(m, points[indices[3 * g]])
            pb = wp.transform_point(m, points[indices[3 * g + 1]])
            pc = wp.transform_point(m, points[indices[3 * g + 2]])
            cull = cut.cull[tri]
            if batch.cull_off[i] != 0:
                cull = 0
            elif batch.mirrored[i] != 0:
                cull = -cull  # the transform turns the outward side inward
        else:
            ia = indices[3 * tri]
            ib = indices[3 * tri + 1]
            ic = indices[3 * tri + 2]
            cull = cut.cull[tri]
            if not wp.static(preproj) or cull != 0:  # preproj: the points only for the facing test
                pa = points[ia]
                pb = points[ib]
                pc = points[ic]
        if cull == CULL_SKIP:
            return
        if cull != 0:
            # closed surface: only faces turned toward the light can be nearest (+1 outward, -1 inward)
            n = wp.cross(pb - pa, pc - pa)
            toward = wp.dot(n, lv.az) < 0.0
            if wp.static(persp):
                toward = wp.dot(n, pa - lv.origin) < 0.0
            if toward != (cull > 0):
                return
        a = wp.vec3(0.0)
        b = wp.vec3(0.0)
        c = wp.vec3(0.0)
        if wp.static(preproj):
            a = proj[ia]  # texel x, y and view depth
            b = proj[ib]
            c = proj[ic]
        else:
            a = view_of(lv, pa)
            b = view_of(lv, pb)
            c = view_of(lv, pc)
        zmax = wp.max(a[2], wp.max(b[2], c[2]))
        zmin = wp.min(a[2], wp.min(b[2], c[2]))
        clipped = False
        if wp.static(persp):
            if zmax < lv.near or zmin > lv.far:
                return
            clipped = zmin < lv.near
        ta = wp.vec2(0.0)
        tb = wp.vec2(0.0)
        tc = wp.vec2(0.0)
        if not clipped:
            if wp.static(preproj):
                ta = wp.vec2(a[0], a[1])
                tb = wp.vec2(b[0], b[1])
                tc = wp.vec2(c[0], c[1])
            else:
                ta = texel_of(lv, a)
                tb = texel_of(lv, b)
                tc = texel_of(lv, c)
        if wp.static(defer_big):
            if clipped:
                big[item] = 1
                return
            bw = wp.min(wp.max(ta[0], wp.max(tb[0], tc[0])), float(lv.width)) - wp.max(wp.min(ta[0], wp.min(tb[0], tc[0])), 0.0)
            bh = wp.min(wp.max(ta[1], wp.max(tb[1], tc[1])), float(lv.height)) - wp.max(wp.min(ta[1], wp.min(tb[1], tc[1])), 0.0)
            if bw < 0.0 or bh < 0.0:
                return
            if bw * bh > big_texels:
                big[item] = 1
                return
        alpha_on = int(0)
        if wp.static(alpha):
            if cut.tri_cut[tri] >= 0:
                alpha_on = 1
        ea = wp.vec3(1.0, 0.0, 0.0)
        eb = wp.vec3(0.0, 1.0, 0.0)
        ec = wp.vec3(0.0, 0.0, 1.0)
        if not clipped:
            raster_triangle(lv, tri, ta, tb, tc, a[2], b[2], c[2], ea, eb, ec, row0, row1, cut, alpha_on, target)
            return
        if wp.static(preproj):  # clipping needs the corners' view-space x, y
            a = view_of(lv, points[ia])
            b = view_of(lv, points[ib])
            c = view_of(lv, points[ic])
        # Sutherland-Hodgman against z >= near: 1 or 2 triangles
        n_in = int(0)
        if a[2] >= lv.near:
            n_in += 1
        if b[2] >= lv.near:
            n_in += 1
        if c[2] >= lv.near:
            n_in += 1
        # rotate so that the odd vertex is first
        p0 = a
        p1 = b
        p2 = c
        w0 = ea
        w1 = eb
        w2 = ec
        odd_in = n_in == 1
        if (b[2] >= lv.near) == odd_in:
            p0 = b
            p1 = c
            p2 = a
            w0 = eb
            w1 = ec
            w2 = ea
        elif (c[2] >= lv.near) == odd_in:
            p0 = c
            p1 = a
            p2 = b
            w0 = ec
            w1 = ea
            w2 = eb
        k01 = clip_point(p0, p1, lv.near)
        k02 = clip_point(p0, p2, lv.near)
        q01 = wp.vec3(k01[0], k01[1], k01[2])
        q02 = wp.vec3(k02[0], k02[1], k02[2])
        u01 = w0 + (w1 - w0) * k01[3]
        u02 = w0 + (w2 - w0) * k02[3]
        if odd_in:  # only p0 in front: one triangle p0, q01, q02
            raster_triangle(lv, tri, texel_of(lv, p0), texel_of(lv, q01), texel_of(lv, q02), p0[2], q01[2], q02[2], w0, u01, u02, row0, row1, cut, alpha_on, target)
        else:  # p0 behind: quad q01, p1, p2, q02
            t01 = texel_of(lv, q01)
            t2 = texel_of(lv, p2)
            raster_triangle(lv, tri, t01, texel_of(lv, p1), t2, q01[2], p1[2], p2[2], u01, w1, w2, row0, row1, cut, alpha_on, target)
            raster_triangle(lv, tri, t01, t2, texel_of(lv, q02), q01[2], p2[2], q02[2], u01, w2, u02, row0, row1, cut, alpha_on, target)

    return wp.kernel(rasterize_triangles, module="unique")


@dataclass
class RasterStats:
    """What a run did: private targets merged (CPU), triangles in the banded second pass, bands."""

    private_targets: int = 0
    big_triangles: int = 0
    bands: int = 0


@dataclass
class InstanceRun:
    """The instances of one prototype to draw in a :meth:`Rasterizer.run`: ``count`` instances of the
    :class:`InstanceBatch`, whose triangles index ``points`` / ``indices`` (the prototypes')."""

    batch: object  # InstanceBatch
    count: int
    points: wp.array
    indices: wp.array


@dataclass
class _Segment:
    """What one part of a run draws: its geometry arrays, batch, work items (``ntri``), the length of
    its big-triangle flags (``items``), whether it is listed / instanced, and its triangle list."""

    points: wp.array
    indices: wp.array
    batch: object
    ntri: int
    items: int
    listed: bool
    instanced: bool
    tri_list: wp.array
    proj: wp.array = None  # the points' texel coordinates and depths (:func:`project_points`), or None


@dataclass(eq=False)
class Rasterizer:
    """Kernels of one (projection, fragment, conservative, alpha, inner) combination and their
    scheduling. Made by :func:`make_rasterizer`; kernels are generated on first use."""

    persp: bool
    spec: FragmentSpec
    conservative: bool
    alpha: bool
    inner: bool = False
    _kernels: dict = field(default_factory=dict)

    def kernel(self, listed: bool, defer_big: bool, instanced: bool = False, preproj: bool = False):
        preproj = preproj and not instanced  # an instance's points are placed per instance: never projected first
        key = (listed, defer_big, instanced, preproj)
        if key not in self._kernels:
            self._kernels[key] = _make_kernel(self.persp, self.spec, self.conservative, self.alpha, listed, defer_big, self.inner, instanced, preproj)
        return self._kernels[key]

    def run(self, points: wp.array, indices: wp.array, cut: Surfaces, view, target, device: str, *,
            triangles: wp.array | None = None, initialized: bool = True, strategy: str = "auto",
            batches: "list[InstanceRun] | None" = None, preproject: bool | None = None) -> RasterStats:
        """Rasterize the triangles (all of ``indices``, or the index list ``triangles``) into ``target``.

        ``initialized = False``: ``target`` holds no data yet; the CPU's first worker clears it as
        its private target (saves a clear and a merge). ``strategy``: ``auto`` (private targets
        when the fragment can merge, else bands), ``private`` or ``bands``. ``batches``: instances
        drawn in the same run (:class:`InstanceRun`: one per prototype, its work items (instance,
        prototype triangle)), sharing the CPU's private targets and their one merge with the
        triangles of ``indices``. ``preproject``: project every point once first (:func:`project_points`)
        rather than each triangle's corners; default: yes, unless a triangle list is shorter than a third
        of the point count. The map is the same bit for bit either way."""
        lv = view.gpu() if isinstance(view, LightView) else view
        if bool(lv.persp) != self.persp:
            raise ValueError("the view's projection does not match the rasterizer's")
        w, h = lv.width, lv.height
        listed = triangles is not None
        no_list = triangles if listed else wp.zeros(1, dtype=wp.int32, device=device)
        no_big = wp.zeros(1, dtype=wp.int32, device=device)
        no_proj = wp.zeros(1, dtype=wp.vec3, device=device)
        # segments: the soup's triangles, then each prototype's instances
        segs = [_Segment(points, indices, _no_batch(device), indices.shape[0] // 3 if triangles is None else triangles.shape[0],
                         indices.shape[0] // 3, listed, False, no_list)]
        for br in batches or ():
            n = int(br.count) * int(br.batch.ntri)
            segs.append(_Segment(br.points, br.indices, br.batch, n, n, False, True, no_list))
        segs = [g for g in segs if g.ntri > 0]
        if preproject is None:
            preproject = bool(segs) and not segs[0].instanced and 3 * segs[0].ntri >= points.shape[0]
        if preproject and segs and not segs[0].instanced:
            # project each point once rather than each triangle's corners: worth it unless a short
            # triangle list uses few of the points
            segs[0].proj = wp.empty(points.shape[0], dtype=wp.vec3, device=device)
            launch_chunked(project_points, points.shape[0], inputs=[points, lv], outputs=[segs[0].proj], device=device, min_chunk=1 << 15)
        ntri = sum(g.ntri for g in segs)
        stats = RasterStats()
        if strategy == "auto":
            strategy = "private" if self.spec.merge is not None else "bands"
        if strategy == "private" and self.spec.merge is None:
            raise ValueError(f"fragment {self.spec.name} cannot merge private targets")

        def launcher(g: "_Segment"):
            def launch(kernel, tgt, start, count, nbands, band_rows, band_start=0, tri_list=g.tri_list, big_texels=0.0, big=no_big):
                wp.launch(kernel, dim=(nbands, count), inputs=[start, band_start, band_rows, tri_list, float(big_texels), g.points, g.indices, lv, cut,
                                                               g.batch, no_proj if g.proj is None else g.proj], outputs=[tgt, big], device=device)

            return launch

        if ntri == 0:
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            return stats
        if not device.startswith("cpu"):
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            nb = (h + GPU_BAND_ROWS - 1) // GPU_BAND_ROWS
            for g in segs:
                launcher(g)(self.kernel(g.listed, False, g.instanced, g.proj is not None), target, 0, g.ntri, nb, GPU_BAND_ROWS)
            stats.bands = nb
            return stats
        if strategy == "bands":
            if not initialized and self.spec.clear is not None:
                self.spec.clear(target, device)
            for g in segs:
                self._bands(launcher(g), self.kernel(g.listed, False, g.instanced, g.proj is not None), target, g.ntri, h, g.tri_list, stats, device)
            return stats
        # CPU phase 1: each worker rasterizes interleaved chunks of small triangles into its own target
        kernels1 = [self.kernel(g.listed, True, g.instanced, g.proj is not None) for g in segs]
        for k in kernels1:
            ensure_loaded(k, device)
        target_bytes = 4 * w * h
        nchunks = sum((g.ntri + CPU_CHUNK - 1) // CPU_CHUNK for g in segs)
        nmaps = max(1, min(cpu_threads(), PRIVATE_BUDGET // max(target_bytes, 1), nchunks))
        own = 0 if initialized else 1  # workers that adopt the (uninitialised) target itself
        privates = [target] * own + [self.spec.private(target, device) for _ in range(nmaps - own)]
        chunks = [(j, s0, min(CPU_CHUNK, g.ntri - s0)) for j, g in enumerate(segs) for s0 in range(0, g.ntri, CPU_CHUNK)]
        bigs = [wp.zeros(g.items, dtype=wp.int32, device=device) for g in segs]  # flags by triangle index (by work item for instances)
        launches = [launcher(g) for g in segs]

        def worker(m):
            def run():
                self.spec.clear(privates[m], device)
                for j, start, count in chunks[m::nmaps]:
                    launches[j](kernels1[j], privates[m], start, count, 1, h, big_texels=BIG_TRIANGLE_TEXELS, big=bigs[j])

            return run

        run_tasks([worker(m) for m in range(nmaps)], device)
        self.spec.merge(privates[own:], target, device)
        stats.private_targets = nmaps
        # CPU phase 2: large (and near-clipped) triangles, shared out by disjoint bands of rows
        for j, g in enumerate(segs):
            big_list = np.flatnonzero(bigs[j].numpy()).astype(np.int32)
            stats.big_triangles += int(len(big_list))
            if len(big_list):
                blist = wp.array(big_list, dtype=wp.int32, device=device)
                self._bands(launches[j], self.kernel(True, False, g.instanced, g.proj is not None), target, len(big_list), h, blist, stats, device)
        return stats

    @staticmethod
    def _bands(launch, kernel, target, ntri, h, tri_list, stats, device):
        """Every worker a disjoint band of rows, every triangle (its rows clipped to the band)."""
        ensure_loaded(kernel, device)
        nb = max(1, min(h, cpu_threads() * 4))
        rows = (h + nb - 1) // nb
        nb = (h + rows - 1) // rows
        stats.bands = nb

        def band_task(b):
            return lambda: launch(kernel, target, 0, ntri, 1, rows, band_start=b, tri_list=tri_list)

        run_tasks([band_task(b) for b in range(nb)], device)


_RASTERIZERS: dict[tuple, Rasterizer] = {}
_NO_BATCH: dict[str, InstanceBatch] = {}


def _no_batch(device: str) -> InstanceBatch:
    """The batch a run without instances passes (never read)."""
    if device not in _NO_BATCH:
        b = InstanceBatch()
        b.to_world = wp.array(np.eye(4, dtype=np.float32)[None], dtype=wp.mat44, device=device)
        b.cull_off = wp.zeros(1, dtype=wp.int32, device=device)
        b.mirrored = wp.zeros(1, dtype=wp.int32, device=device)
        b.ntri, b.first, b.tri0 = 1, 0, 0
        _NO_BATCH[device] = b
    return _NO_BATCH[device]


def make_rasterizer(view, fragment_func, *, conservative: bool = False, alpha: bool = False, inner: bool = False) -> Rasterizer:
    """The rasterizer of ``view``'s projection (``"perspective"``, ``"orthographic"``, a
    :class:`LightView` or a :class:`ViewGPU`) that calls ``fragment_func`` (a fragment made with
    :func:`fragment`) per covered texel, conservative or not (``inner``: only texels covered whole,
    at their farthest depth; needs ``conservative``), alpha-tested or not. Cached."""
    if inner and not conservative:
        raise ValueError("inner coverage is a conservative mode: pass conservative=True")
    if isinstance(view, str):
        if view not in (PERSPECTIVE, ORTHOGRAPHIC):
            raise ValueError(f"view {view!r} is not {PERSPECTIVE} or {ORTHOGRAPHIC}")
        persp = view == PERSPECTIVE
    else:
        persp = bool(view.persp)
    spec = FRAGMENTS.get(getattr(fragment_func, "key", None))
    if spec is None or spec.func is not fragment_func:
        raise ValueError(f"{fragment_func!r} is not a registered fragment (make it with @fragment)")
    key = (persp, spec.name, bool(conservative), bool(alpha), bool(inner))
    if key not in _RASTERIZERS:
        _RASTERIZERS[key] = Rasterizer(persp, spec, bool(conservative), bool(alpha), bool(inner))
    return _RASTERIZERS[key]
