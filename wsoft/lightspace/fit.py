"""Fitting a light view to the receivers the camera sees (:func:`fit_light_view`): a perspective
frustum from a local light's centre (at most ±80° off its axis), an orthographic box along a
distant light, windows grown for soft casters, depth ranges from the nearest caster to the
farthest receiver; the receivers' bounds reduced by row blocks over the thread pool."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wsoft.lightspace.view import MAX_TAN, LightView, far_light, frame_extent_of_bounds, to_frame
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISTANT, LIGHT_POINT, LIGHT_SPHERE, Light


def _basis_from_axis(z: np.ndarray) -> np.ndarray:
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def omni_axes(light: Light, d: np.ndarray) -> np.ndarray:
    """The view axes (columns x, y, view axis) of a light that emits all around (sphere, point,
    cylinder) looking along ``d``: a cylinder light's x axis is its own axis projected onto the
    view's plane (its bound is then a rectangle along the view's x and y,
    :func:`~wsoft.lightspace.light.cylinder_half_extents`; seen end-on, any x)."""
    if light.kind != LIGHT_CYLINDER:
        return _basis_from_axis(d)
    z = np.asarray(d, np.float64) / np.linalg.norm(d)
    a = np.asarray(light.frame, np.float64)[:, 0]
    x = a - np.dot(a, z) * z
    if np.linalg.norm(x) < 1e-6:
        return _basis_from_axis(z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def distant_axes(light: Light) -> np.ndarray:
    """A distant light's view axes (columns x, y, view axis): its frame, looking along its emission."""
    return np.stack([light.frame[:, 0], light.frame[:, 1], -light.frame[:, 2]], axis=1)


def local_axes(light: Light) -> np.ndarray:
    """A rect or disk light's view axes (columns x, y, view axis): its frame, right-handed, looking along −Z."""
    return np.stack([light.frame[:, 0], -light.frame[:, 1], -light.frame[:, 2]], axis=1)


def _frame_bounds(p: np.ndarray, origin: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) per axis of :func:`to_frame` of the points ``p`` (N >= 1), by row blocks over
    the thread pool without keeping the transformed points: the same values as transforming
    them all and reducing."""
    from wsoft.parallel import run_row_blocks

    parts = []

    def block(a: int, e: int) -> None:
        v = to_frame(p[a:e], origin, axes, threads=False)
        parts.append((v.min(axis=0), v.max(axis=0)))

    run_row_blocks(len(p), block)
    return np.min([q[0] for q in parts], axis=0), np.max([q[1] for q in parts], axis=0)


def _caster_growth(casters: np.ndarray, origin: np.ndarray, axes: np.ndarray, window, half_extent: float, zmin: float,
                   zr_max: float) -> float | None:
    """How far a local light's window (tangents l, r, b, t) must grow for soft shadows: the largest
    ``half_extent * (1/z - 1/zr_max)`` over the casters at view depth ``zmin < z < zr_max`` whose
    tangents lie within that distance of the window (None: no such caster). Row blocks over the
    thread pool, as :func:`to_frame`."""
    from wsoft.parallel import run_row_blocks

    l, r, b, t = window
    found = []

    def block(a: int, e: int) -> None:
        vc = to_frame(casters[a:e], origin, axes, threads=False)
        vc = vc[(vc[:, 2] > zmin) & (vc[:, 2] < zr_max)]
        if len(vc):
            grow = half_extent * (1.0 / vc[:, 2] - 1.0 / zr_max)
            cx, cy = vc[:, 0] / vc[:, 2], vc[:, 1] / vc[:, 2]
            near_window = (cx >= l - grow) & (cx <= r + grow) & (cy >= b - grow) & (cy <= t + grow)
            if near_window.any():
                found.append(float(grow[near_window].max()))

    run_row_blocks(len(casters), block)
    return max(found) if found else None


def _prism_depth_min(v: np.ndarray, window, default: float) -> float:
    """Smallest view depth of the view-space points ``v`` inside an orthographic window's prism
    (``default`` if none)."""
    if v is None or len(v) == 0:
        return default
    l, r, b, t = window
    from wsoft.parallel import run_row_blocks

    found = []

    def block(a: int, e: int) -> None:  # row blocks over the thread pool, as to_frame
        w = v[a:e]
        inside = (w[:, 0] >= l) & (w[:, 0] <= r) & (w[:, 1] >= b) & (w[:, 1] <= t)
        if inside.any():
            found.append(float(w[inside, 2].min()))

    run_row_blocks(len(v), block)
    return min(found + [default])


def cone_planes(window, zr_max: float, tan_a: float) -> np.ndarray:
    """The region of a distant light's view (view space: x, y across, z along the light) where a
    caster can block part of the light's cone (half-angle tangent ``tan_a``) from a receiver in the
    window ``(l, r, b, t)`` no deeper than ``zr_max``: points at depth ``z <= zr_max`` within
    ``tan_a * (zr_max - z)`` of the window on each axis (``tan_a = 0``: the window's prism up to
    ``zr_max``). Five planes ``(n, d)`` as rows ``[nx, ny, nz, d]``, inside where ``n . p + d >= 0``."""
    l, r, b, t = window
    k, z = float(tan_a), float(zr_max)
    kz = k * z if k else 0.0  # zr_max may be inf (the whole prism) where tan_a is 0
    return np.array([[1.0, 0.0, -k, kz - l], [-1.0, 0.0, -k, kz + r], [0.0, 1.0, -k, kz - b], [0.0, -1.0, -k, kz + t],
                     [0.0, 0.0, -1.0, z]])


def _plane_values(p: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """``n . p + d`` of the points ``p`` (``[..., 3]``) for each plane row ``[nx, ny, nz, d]``:
    ``[..., planes]``, without BLAS (see :func:`to_frame`)."""
    p = p[..., None, :]
    return p[..., 0] * planes[:, 0] + p[..., 1] * planes[:, 1] + p[..., 2] * planes[:, 2] + planes[:, 3]


def _cone_depth_min(v: np.ndarray | None, planes: np.ndarray, default: float) -> float:
    """Smallest view depth of the view-space points ``v`` inside the region of :func:`cone_planes`
    (``default`` if none: only the points nearer are tested); row blocks over the thread pool, as
    :func:`to_frame`."""
    if v is None or len(v) == 0:
        return default
    from wsoft.parallel import run_row_blocks

    found = []

    def block(a: int, e: int) -> None:
        w = v[a:e]
        w = w[w[:, 2] < default]  # a point no nearer than ``default`` cannot lower it
        inside = np.all(_plane_values(w, planes) >= 0.0, axis=-1)
        if inside.any():
            found.append(float(w[inside, 2].min()))

    run_row_blocks(len(v), block)
    return min(found + [default])


def clipped_depth_min(tris: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Per triangle (view space, float64 ``[M, 3, 3]``), the smallest depth (z) of its part inside
    the convex region ``planes`` (rows ``[nx, ny, nz, d]``, inside where ``n . p + d >= 0``): the
    triangle clipped by each plane in turn (Sutherland-Hodgman; a convex polygon gains at most one
    corner per plane); ``inf`` where nothing of it is inside."""
    m = len(tris)
    kmax = 3 + len(planes)
    poly = np.zeros((m, kmax, 3))
    poly[:, :3] = tris
    cnt = np.full(m, 3)
    rows = np.arange(m)
    for pl in planes:
        s = _plane_values(poly, pl[None])[..., 0]
        out = np.zeros_like(poly)
        oc = np.zeros(m, int)
        for j in range(kmax - 1):
            valid = j < cnt
            if not valid.any():
                break
            jn = np.where(valid, (j + 1) % np.maximum(cnt, 1), 0)
            vi, vn = poly[:, j], poly[rows, jn]
            si, sn = s[:, j], s[rows, jn]
            keep = valid & (si >= 0.0)
            out[rows[keep], oc[keep]] = vi[keep]
            oc += keep
            cross = valid & ((si >= 0.0) != (sn >= 0.0))
            if cross.any():
                tt = (si[cross] / (si[cross] - sn[cross]))[:, None]
                out[rows[cross], oc[cross]] = vi[cross] + tt * (vn[cross] - vi[cross])
                oc += cross
        poly, cnt = out, oc
    z = np.where(np.arange(kmax)[None, :] < cnt[:, None], poly[:, :, 2], np.inf)
    return z.min(axis=1)


def _triangle_depth_min(mesh, origin: np.ndarray, axes: np.ndarray, planes: np.ndarray, default: float) -> float:
    """Smallest view depth of the parts of the triangles ``mesh`` (world points ``[V, 3]``, triangles
    ``[T, 3]`` into them) inside the region ``planes`` of the view at ``origin`` along ``axes``
    (:func:`cone_planes`), their interiors included: a triangle whose corners all lie outside may
    cross it (a huge wall far off). A triangle whose corners all lie at ``default`` or deeper is not
    looked at (it cannot be nearer); of the others, those wholly inside give their corners' depth,
    those outside one plane are skipped, the rest are clipped (:func:`clipped_depth_min`).
    ``default`` if none. Row blocks over the thread pool."""
    pts, tris = mesh
    pts = np.asarray(pts)
    tris = np.asarray(tris).reshape(-1, 3)
    if len(tris) == 0:
        return default
    from wsoft.parallel import run_row_blocks

    depth = np.empty(len(pts), np.float64)

    def depths(a: int, e: int) -> None:  # the view depth of every point, alone (the cheap test first)
        d = pts[a:e] - origin
        depth[a:e] = d[:, 0] * axes[0, 2] + d[:, 1] * axes[1, 2] + d[:, 2] * axes[2, 2]

    run_row_blocks(len(pts), depths)
    found = []

    def block(a: int, e: int) -> None:
        t = tris[a:e]
        t = t[np.minimum(np.minimum(depth[t[:, 0]], depth[t[:, 1]]), depth[t[:, 2]]) < default]
        if not len(t):
            return
        w = to_frame(pts[t.ravel()], origin, axes, threads=False).reshape(-1, 3, 3)
        s = _plane_values(w, planes)  # [n, 3 corners, planes]
        out = np.any(np.all(s < 0.0, axis=1), axis=1)
        inside = np.all(s >= 0.0, axis=(1, 2))
        if inside.any():
            found.append(float(w[inside, :, 2].min()))
        cut = ~out & ~inside
        if cut.any():
            z = clipped_depth_min(w[cut], planes)
            if np.isfinite(z).any():
                found.append(float(z[np.isfinite(z)].min()))

    run_row_blocks(len(tris), block)
    return min(found + [default])


def distant_caster_depth(vp: np.ndarray | None, window, zr_min: float, zr_max: float, tan_a: float,
                         mesh=None, origin: np.ndarray | None = None, axes: np.ndarray | None = None) -> float:
    """Where a distant light's depth range starts: the smallest view depth of the casters that can
    block part of its cone (half-angle tangent ``tan_a``; 0: its central direction) from a receiver
    in ``window`` at depth ``<= zr_max`` (the region of :func:`cone_planes`), and ``zr_min`` when
    none is nearer. ``vp``: the caster points in view space; ``mesh``: the casting triangles
    (world points ``[V, 3]``, triangles ``[T, 3]``) of the view at ``origin`` along ``axes``, whose
    interiors count too (a huge wall far off whose corners all lie outside the region). The window then grows by ``tan_a * (zr_max - depth)`` on every side
    to hold every such caster: a caster at depth z counts only within ``tan_a * (zr_max - z)`` of
    the window, which is never more."""
    planes = cone_planes(window, zr_max, tan_a)
    zc = _cone_depth_min(vp, planes, zr_min)
    if mesh is not None:
        zc = _triangle_depth_min(mesh, origin, axes, planes, zc)
    return zc


FIT_BLOCK = 8192  # points a thread of the fit's reduction kernels walks (one row of partial results each)
F64_BIG = wp.constant(wp.float64(1.0e300))


@wp.kernel
def bounds_partials(
    offset: int,
    n: int,
    pts: wp.array[wp.vec3],
    # outputs
    part: wp.array2d[wp.float64],
):
    """Per block of :data:`FIT_BLOCK` points: min (3), max (3) and sum (3) of the coordinates, in float64."""
    b = wp.tid() + offset
    lo = wp.vec3d(F64_BIG, F64_BIG, F64_BIG)
    hi = wp.vec3d(-F64_BIG, -F64_BIG, -F64_BIG)
    sm = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    for i in range(b * FIT_BLOCK, wp.min(b * FIT_BLOCK + FIT_BLOCK, n)):
        p = pts[i]
        q = wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))
        lo = wp.min(lo, q)
        hi = wp.max(hi, q)
        sm = sm + q
    for k in range(3):
        part[b, k] = lo[k]
        part[b, 3 + k] = hi[k]
        part[b, 6 + k] = sm[k]


@wp.kernel
def local_fit_partials(
    offset: int,
    n: int,
    pts: wp.array[wp.vec3],
    origin: wp.vec3d,
    axes: wp.mat33d,
    facing: wp.vec3d,
    use_facing: int,
    zmin_ok: wp.float64,
    margin: wp.float64,
    max_tan: wp.float64,
    # outputs
    part: wp.array2d[wp.float64],
):
    """Per block of :data:`FIT_BLOCK` receivers, what a local light's fit needs (see
    :func:`_local_fit_stats`): for ``all`` (columns 0-6) and ``front`` (7-13) the count, l, r, b, t,
    zmin, zmax; column 14 the receivers outside the ±80° window (never those behind the plane),
    column 15 those behind the plane."""
    b = wp.tid() + offset
    zero = wp.float64(0.0)
    cnt = wp.vec2d(zero, zero)
    l = wp.vec2d(F64_BIG, F64_BIG)
    r = wp.vec2d(-F64_BIG, -F64_BIG)
    bo = wp.vec2d(F64_BIG, F64_BIG)
    t = wp.vec2d(-F64_BIG, -F64_BIG)
    zlo = wp.vec2d(F64_BIG, F64_BIG)
    zhi = wp.vec2d(-F64_BIG, -F64_BIG)
    outside = zero
    behind_count = zero
    for i in range(b * FIT_BLOCK, wp.min(b * FIT_BLOCK + FIT_BLOCK, n)):
        p = pts[i]
        d = wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2])) - origin
        # (p - origin) @ axes, in to_frame's order
        vx = d[0] * axes[0, 0] + d[1] * axes[1, 0] + d[2] * axes[2, 0]
        vy = d[0] * axes[0, 1] + d[1] * axes[1, 1] + d[2] * axes[2, 1]
        z = d[0] * axes[0, 2] + d[1] * axes[1, 2] + d[2] * axes[2, 2]
        behind = False
        if use_facing != 0:
            behind = (d[0] * facing[0] + d[1] * facing[1] + d[2] * facing[2]) >= zero
            if behind:
                behind_count += wp.float64(1.0)
        if z > zmin_ok:
            tx = vx / z
            ty = vy / z
            mz = zero
            if margin > zero:
                mz = margin / wp.max(z, zmin_ok)
            if not behind and (wp.abs(tx) > max_tan or wp.abs(ty) > max_tan):
                outside += wp.float64(1.0)
            for k in range(2):
                if k == 0 or not behind:
                    cnt[k] = cnt[k] + wp.float64(1.0)
                    l[k] = wp.min(l[k], tx - mz)
                    r[k] = wp.max(r[k], tx + mz)
                    bo[k] = wp.min(bo[k], ty - mz)
                    t[k] = wp.max(t[k], ty + mz)
                    zlo[k] = wp.min(zlo[k], z)
                    zhi[k] = wp.max(zhi[k], z)
        elif not behind:
            outside += wp.float64(1.0)
    for k in range(2):
        part[b, 7 * k] = cnt[k]
        part[b, 7 * k + 1] = l[k]
        part[b, 7 * k + 2] = r[k]
        part[b, 7 * k + 3] = bo[k]
        part[b, 7 * k + 4] = t[k]
        part[b, 7 * k + 5] = zlo[k]
        part[b, 7 * k + 6] = zhi[k]
    part[b, 14] = outside
    part[b, 15] = behind_count


def _fit_points(rec: np.ndarray) -> wp.array:
    """Receivers as a float32 vec3 array on the CPU (no copy when they already are float32)."""
    return wp.array(np.ascontiguousarray(rec, np.float32).reshape(-1, 3), dtype=wp.vec3, device="cpu", copy=False)


def _partials(kernel, pts: wp.array, columns: int, inputs: list) -> np.ndarray:
    """Run a per-block reduction kernel over the thread pool (each block writes its own row)."""
    from wsoft.parallel import launch_chunked

    n = pts.shape[0]
    blocks = max(1, (n + FIT_BLOCK - 1) // FIT_BLOCK)
    part = wp.empty((blocks, columns), dtype=wp.float64, device="cpu")
    launch_chunked(kernel, blocks, inputs=[n, pts] + inputs, outputs=[part], device="cpu", min_chunk=1, per_thread=2)
    return part.numpy()


def receiver_bounds(pts: wp.array) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(min, max, mean) of the receivers (float64), by :func:`bounds_partials`."""
    pr = _partials(bounds_partials, pts, 9, [])
    return pr[:, 0:3].min(axis=0), pr[:, 3:6].max(axis=0), pr[:, 6:9].sum(axis=0) / max(pts.shape[0], 1)


def _local_fit_stats(pts: wp.array, origin: np.ndarray, axes: np.ndarray, facing: np.ndarray | None, zmin_ok: float, margin: float) -> dict:
    """What a local light's view fit needs of the receivers (:func:`local_fit_partials` over the
    CPU thread pool, in float64): for the receivers in front of the light's origin (``all``) and,
    when ``facing`` (the light's emission axis) is given, those also in front of its plane
    (``front``): their count, the window (l, r, b, t: tangents widened by ``margin`` at each one's
    depth), depth range and how many lie beyond the ±80° window (``outside``, never counting those
    behind the plane) and how many lie behind the plane (``behind``)."""
    f = np.zeros(3) if facing is None else np.asarray(facing, np.float64)
    pr = _partials(local_fit_partials, pts, 16,
                   [wp.vec3d(*np.asarray(origin, np.float64)), wp.mat33d(*np.asarray(axes, np.float64).ravel()), wp.vec3d(*f),
                    int(facing is not None), wp.float64(zmin_ok), wp.float64(margin), wp.float64(MAX_TAN)])
    outside = int(pr[:, 14].sum())
    res = {"behind": int(pr[:, 15].sum())}
    for k, key in enumerate(("all", "front")):
        c = pr[:, 7 * k: 7 * k + 7]
        n = int(c[:, 0].sum())
        res[key] = {"n": n, "outside": outside}
        if n:
            res[key].update(l=float(c[:, 1].min()), r=float(c[:, 2].max()), b=float(c[:, 3].min()), t=float(c[:, 4].max()),
                            zmin=float(c[:, 5].min()), zmax=float(c[:, 6].max()))
    return res


_NEAREST: list = []  # (caster points, origin, axis, depth of the nearest in front): the last few lights' scans


def nearest_caster_depth(pts: np.ndarray, origin: np.ndarray, axis: np.ndarray) -> float:
    """The depth along ``axis`` from ``origin`` of the nearest of the caster points ``pts`` in front
    of it (inf: none): a scan of every point, kept for the same points array and light (a scene's
    :attr:`~wsoft.scene.types.Scene.caster_points` is one array), so a still light scans once."""
    o = np.asarray(origin, np.float64)
    a = np.asarray(axis, np.float64)
    for p, oo, aa, d in _NEAREST:
        if p is pts and np.array_equal(oo, o) and np.array_equal(aa, a):
            return d
    p32 = np.asarray(pts, np.float32).reshape(-1, 3)
    z = (p32 - o.astype(np.float32)) @ a.astype(np.float32)
    front = z[z > 0.0]
    d = float(front.min()) if front.size else math.inf
    _NEAREST.insert(0, (pts, o, a, d))
    del _NEAREST[8:]
    return d


def local_near(ext: float, zmin: float | None, all_casters, origin: np.ndarray, axes: np.ndarray) -> tuple[float, float]:
    """A local light's near plane and the depth of the nearest caster vertex in front of it
    (:func:`nearest_caster_depth` of ``all_casters()``, the scene's caster points; inf: none). The
    near plane: 1e-4 of the frame's extent, or half the depth of the nearest receiver (``zmin``;
    None: no receiver in front) or of the nearest caster vertex when either lies nearer, so that a
    caster just in front of the light (a grille, a lamp's diffuser) is mapped, not clipped; a
    caster brings it no nearer than 2 float32 ulps of the light's largest coordinate, the rounding
    of a view depth there."""
    near = max(1e-4 * ext, 1e-7)
    if zmin is not None:
        near = min(near, 0.5 * zmin)
    nearest = math.inf
    if all_casters is not None:
        pts = all_casters()
        if len(pts):
            nearest = nearest_caster_depth(pts, origin, np.asarray(axes, np.float64)[:, 2])
    if nearest < 2.0 * near:
        floor = 2.0 * float(np.spacing(np.float32(np.abs(np.asarray(origin, np.float64)).max())))
        near = min(near, max(0.5 * nearest, floor))
    return near, nearest


def near_caster_warning(light: Light, depth: float) -> str:
    """The warning of a soft view whose light has a caster nearer than the light's own size
    (:attr:`~wsoft.lightspace.view.LightView.nearest_caster` below :meth:`Light.extent`)."""
    return (f"light {light.path}: a caster lies {depth:.3g} in front of it, nearer than its size ({light.extent():.3g}): seen from "
            "the light's centre it hides the casters behind it and reaches across the map, while it blocks only part of the light, "
            "so a shadow map's soft shadow of this light is wrong around it (too light where it hides a caster, too dark where "
            "its penumbra is estimated from its depth); trace rays (reference, dcs, rtdenoise) or move the caster away from the light")


def _far_light_depths(casters: np.ndarray, origin: np.ndarray, axes: np.ndarray, zr_min: float, zr_max: float, near: float,
                      ext: float) -> tuple[float, float]:
    """(near, far) of a far local light's view (:func:`fit_light_view`): near just before the
    nearest of the receivers and the caster vertices when every caster vertex lies in front of
    the light (else ``near`` as given: a triangle reaching behind the light can come arbitrarily
    close), far a hundredth of the range past the farthest receiver."""
    pts = np.asarray(casters).reshape(-1, 3)
    if len(pts):
        lo, _ = _frame_bounds(pts, origin, axes)
        if lo[2] > 0.0:
            near = max(near, (1.0 - 1e-3) * min(float(lo[2]), zr_min))
    return near, zr_max + 0.01 * (zr_max - near) + 1e-3 * ext


def fit_light_view(
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
    caster_triangles=None,
) -> LightView:
    """Fit a view of ``light`` to ``receivers`` (world points [N, 3], the camera's visible surface).

    ``margin`` widens the window by a world distance at the receivers; ``margin_texels`` keeps
    a border of texels. ``casters`` (world points, e.g. the scene's vertices) asks for a view
    for soft shadows: the window is widened so that every caster that can block part of the
    *whole* light from a receiver is mapped (for a local light of half-extent w, a caster at
    depth z blocks within w (1/z - 1/z_r) of a receiver's tangent; for a distant light of cone
    half-angle a, within (z_r - z) tan a). Perspective windows are clamped to ±80° around the
    view axis; receivers beyond are counted in ``receivers_outside``. A sphere, point or cylinder
    light's view looks at the receivers' mean (:func:`omni_axes`). A rect or disk light's view is
    fitted to the receivers in front of its emitting plane; those behind it (which get none of its
    light, :mod:`wsoft.raster.horizon`) are counted in ``receivers_behind``, never as outside.
    ``side_growth`` (a local light): per side of the window (l, r, b, t), how far casters beyond
    that edge ask it to grow, found in a coarse depth map around the window (the interior of a
    triangle whose vertices lie far outside, a ceiling just below a lamp, which the vertices miss):
    that side grows at least as far (:meth:`~wsoft.pipeline.context.RenderContext.light_view`).

    Every scale in the view comes from :func:`frame_extent` (receivers and the light), not the
    scene's bounds: a distant light's depth range starts at the nearest caster that can block part
    of its cone from a receiver (:func:`distant_caster_depth`: a caster point within
    ``(z_r - z) tan a`` of the receivers' window, ``casters``, else the scene's bounds' corners
    inside the window's prism), and its window grows by ``(z_r - z) tan a`` for the nearest; a
    caster far off that cannot shadow a receiver moves neither. ``caster_triangles`` (a callable
    giving the casting triangles as world points ``[V, 3]`` and triangles ``[T, 3]`` into them,
    :meth:`Scene.caster_mesh <wsoft.scene.types.Scene.caster_mesh>`; read for a distant light only)
    makes the interiors count too: a huge wall far off whose corners all lie outside that region
    but which crosses it. Without them such a caster keeps its true, smaller depth in the map
    (nearer than the range's start), and the window does not grow for it.

    A local light beyond :data:`~wsoft.lightspace.view.LIGHT_REACH` receiver diagonals of the
    receivers (:func:`~wsoft.lightspace.view.far_light`) gets a depth range fitted to its casters
    and receivers: the near plane just before the nearest caster vertex when every caster vertex
    lies in front of the light (``all_casters``, a callable giving the scene's caster points: a
    triangle's nearest point is one of its vertices), the far plane a hundredth of the range past
    the farthest receiver. Depths normalised over that range keep the caster-to-receiver distance
    resolved however far the light is (from ``near ~ 0`` to a far plane kilometres away, a
    one-unit gap is lost in float32).
    """
    if not 256 <= size <= 8192:
        from wsoft.errors import ParameterError

        raise ParameterError(f"shadow_map_size {size} out of range [256, 8192]")
    rec = np.asarray(receivers).reshape(-1, 3)
    if len(rec) == 0:
        rec = np.stack([scene_lo, scene_hi])
    pts = _fit_points(rec)
    rlo, rhi, rmean = receiver_bounds(pts)
    ext = frame_extent_of_bounds(rlo, rhi, light)
    growth = 0.0
    if light.kind == LIGHT_DISTANT:
        axes = distant_axes(light)
        center = 0.5 * (rlo + rhi)
        vlo, vhi = _frame_bounds(rec, center, axes)
        corners = np.array([[x, y, z] for x in (scene_lo[0], scene_hi[0]) for y in (scene_lo[1], scene_hi[1]) for z in (scene_lo[2], scene_hi[2])])
        pts = casters if casters is not None else corners
        pad = margin + 1e-4 * ext
        l, r = vlo[0] - pad, vhi[0] + pad
        b, t = vlo[1] - pad, vhi[1] + pad
        zr_min, zr_max = float(vlo[2]), float(vhi[2])
        vp = to_frame(np.asarray(pts).reshape(-1, 3), center, axes) if pts is not None and len(pts) else None
        tan_a = math.tan(math.radians(0.5 * light.angle_deg)) if casters is not None and light.angle_deg > 0 else 0.0
        mesh = caster_triangles() if caster_triangles is not None else None
        zc = distant_caster_depth(vp, (l, r, b, t), zr_min, zr_max, tan_a, mesh, center, axes)
        g = tan_a * max(zr_max - zc, 0.0)
        l, r, b, t = l - g, r + g, b - g, t + g
        # the origin a little before the nearest caster: depths stay positive and their float
        # precision is that of the caster-to-receiver distance
        lead = 1e-3 * ext
        origin = center + axes[:, 2] * (zc - lead)
        near = 0.0
        nearest = math.inf
        far = (zr_max - zc) + 2.0 * lead
        persp, outside, behind = False, 0, 0
    else:
        origin = np.asarray(light.position, np.float64)
        if light.kind in (LIGHT_SPHERE, LIGHT_POINT, LIGHT_CYLINDER):
            d = rmean - origin
            axes = omni_axes(light, d if np.linalg.norm(d) > 1e-9 * ext else -light.frame[:, 2])
        else:
            axes = local_axes(light)
        zmin_ok = 1e-6 * ext
        # a rect or disk light emits forward only: receivers behind its plane see nothing of it
        # (the horizon rule darkens them), so they are neither fitted nor counted outside, only counted
        one_sided = light.one_sided
        st = _local_fit_stats(pts, origin, axes, np.asarray(light.frame, np.float64)[:, 2] if one_sided else None, zmin_ok, margin)
        s = st["front"] if one_sided and st["front"]["n"] else st["all"]
        if s["n"]:
            l, r, b, t = s["l"], s["r"], s["b"], s["t"]
        else:
            l, r, b, t = -1.0, 1.0, -1.0, 1.0
        w = light.extent()
        if casters is not None and w > 0 and s["n"]:
            g = _caster_growth(np.asarray(casters).reshape(-1, 3), origin, axes, (l, r, b, t), w, 1e-3 * ext, s["zmax"])
            if g is not None:
                l, r, b, t = l - g, r + g, b - g, t + g
                growth = g
            if side_growth is not None:  # per side (l, r, b, t): casters beyond that edge found in a depth map
                more = [max(x - (g or 0.0), 0.0) for x in side_growth]
                l, r, b, t = l - more[0], r + more[1], b - more[2], t + more[3]
        l, r = max(l, -MAX_TAN), min(r, MAX_TAN)
        b, t = max(b, -MAX_TAN), min(t, MAX_TAN)
        outside = s["outside"]
        behind = st["behind"]
        near, nearest = local_near(ext, s["zmin"] if s["n"] else None, all_casters, origin, axes)
        far = (s["zmax"] if s["n"] else ext) * 1.01 + 1e-3 * ext
        if s["n"] and all_casters is not None and far_light(light, rlo, rhi):
            near, far = _far_light_depths(all_casters(), origin, axes, s["zmin"], s["zmax"], near, ext)
        persp = True
    # keep a border of texels and avoid a zero-area window
    w = max(r - l, 1e-6)
    h = max(t - b, 1e-6)
    ex = w * margin_texels / max(size - 2 * margin_texels, 1)
    ey = h * margin_texels / max(size - 2 * margin_texels, 1)
    window = (l - ex, l + w + ex, b - ey, b + h + ey)
    return LightView(
        light_path=light.path, persp=persp, origin=origin, axes=axes, window=window,
        near=float(near), far=float(far), width=size, height=size, receivers_outside=outside, receivers_behind=behind, extent=ext,
        growth=float(growth), nearest_caster=nearest,
    )
