"""Eye-view G-buffer: world position, normal, camera distance, primitive id, uv per sample.

Primary visibility is resolved by casting one camera ray per sample against the scene's
BVH (alpha-tested through cutouts; back faces of single-sided meshes culled, as
``doubleSided = false`` allows), which gives exact positions for the shadow passes.
``k`` samples per pixel use a fixed MSAA-like pattern.

Samples are stored sample-major: ``k * H * W`` entries, layer ``s`` (the ``s``-th sample of
every pixel) after layer ``s - 1``. Kernels take the G-buffer as one :class:`GBufferGPU` struct
and find their way with :func:`gb_pixel`, :func:`gb_layer`, :func:`gb_index` and
:func:`gb_neighbour` (never by decoding flat indices by hand).

A *bake* G-buffer (:func:`bake_gbuffer`) holds given points on surfaces instead of camera-ray
hits (mesh vertices, texel centres), packed into a near-square ``W x H`` image of one layer with
no pixel grid (``grid = 0``): its samples are independent points, so :func:`gb_neighbour` finds
none (a point has no pixel footprint).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wsoft.lightspace.view import ViewGPU, in_front_of_light, inside_map, map_coords, normalised_depth, texel_of, view_of
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU
from wsoft.scene.device import DeviceScene
from wsoft.scene.instancing import InstancesGPU
from wsoft.scene.rays import nearest_hit
from wsoft.scene.surfaces import Surfaces


@wp.func
def radical_inverse2(i: int) -> float:
    r = float(0.0)
    f = float(0.5)
    n = i
    while n > 0:
        if n % 2 == 1:
            r += f
        f *= 0.5
        n = n // 2
    return r


@wp.func
def camera_ray(cam: CameraGPU, width: int, height: int, fx: float, fy: float):
    """The camera ray through image point (``fx``, ``fy``) (pixel units, (0, 0) the top-left corner
    of the image): (origin, unit direction, distance to the near plane, to the far plane)."""
    ndc_x = fx / float(width) * 2.0 - 1.0
    ndc_y = 1.0 - fy / float(height) * 2.0
    wx = ndc_x * cam.tan_half[0] + cam.offset[0]
    wy = ndc_y * cam.tan_half[1] + cam.offset[1]
    o = cam.origin
    d = wp.normalize(cam.ax * wx + cam.ay * wy - cam.az)
    t0 = cam.near / wp.max(wp.dot(d, -cam.az), 1.0e-6)
    t1 = cam.far / wp.max(wp.dot(d, -cam.az), 1.0e-6)
    if cam.ortho != 0:
        o = cam.origin + cam.ax * wx + cam.ay * wy
        d = -cam.az
        t0 = cam.near
        t1 = cam.far
    return o, d, t0, t1


@wp.func
def cast_primary_scaled(mesh: wp.uint64, cut: Surfaces, has_cutouts: int, inst: InstancesGPU, cam: CameraGPU, width: int, height: int,
                        fx: float, fy: float):
    """The camera ray through image point (``fx``, ``fy``) (:func:`camera_ray`) against the scene
    (the soup's ``mesh``, then the instances of ``inst``, :func:`~wsoft.scene.rays.nearest_hit`): (found
    0/1, world point, viewer-facing normal, triangle (combined index), u, v, camera distance, the
    point's rounding scale). The point is the one the triangle's corners give at the hit's weights
    (a few ulps of the triangle's coordinates off its plane, however far the camera), the scale
    what :func:`~wsoft.scene.offsets.ray_offset` takes. Alpha-tested through cutouts; back faces
    of single-sided meshes skipped."""
    o, d, t0, t1 = camera_ray(cam, width, height, fx, fy)
    found, travelled, face, bu, bv, n, p, scale = nearest_hit(mesh, cut, has_cutouts, inst, o + d * t0, d, t1 - t0, t0)
    if found == 0:
        p = o + d * travelled
    if wp.dot(n, d) > 0.0:
        n = -n
    return found, p, n, face, bu, bv, wp.length(p - o), scale


@wp.func
def cast_primary(mesh: wp.uint64, cut: Surfaces, has_cutouts: int, inst: InstancesGPU, cam: CameraGPU, width: int, height: int,
                 fx: float, fy: float):
    """:func:`cast_primary_scaled` without the scale: (found 0/1, world point, viewer-facing normal,
    triangle (combined index), u, v, camera distance)."""
    found, p, n, face, bu, bv, dist, scale = cast_primary_scaled(mesh, cut, has_cutouts, inst, cam, width, height, fx, fy)
    return found, p, n, face, bu, bv, dist


@wp.func
def pixel_sample_offset(s: int, spp: int) -> wp.vec2:
    """Where the ``s``-th of ``spp`` G-buffer samples lies in its pixel ([0, 1)^2; the centre for one)."""
    if spp > 1:
        return wp.vec2((float(s) + 0.5) / float(spp), wp.mod(radical_inverse2(s) + 0.5 / float(spp), 1.0))
    return wp.vec2(0.5, 0.5)


@wp.kernel
def trace_gbuffer(
    offset: int,
    mesh: wp.uint64,
    cut: Surfaces,
    has_cutouts: int,
    inst: InstancesGPU,
    cam: CameraGPU,
    width: int,
    height: int,
    spp: int,
    # outputs
    pos: wp.array[wp.vec3],
    nrm: wp.array[wp.vec3],
    dist: wp.array[float],
    prim: wp.array[wp.int32],
    uv: wp.array[wp.vec2],
    bary: wp.array[wp.vec2],
    err: wp.array[float],
):
    idx = wp.tid() + offset
    npix = width * height
    s = idx // npix
    pix = idx - s * npix
    row = pix // width
    col = pix - row * width
    so = pixel_sample_offset(s, spp)
    found, p, n, face, bu, bv, d, scale = cast_primary_scaled(mesh, cut, has_cutouts, inst, cam, width, height, float(col) + so[0],
                                                              float(row) + so[1])
    if found == 1:
        pos[idx] = p
        nrm[idx] = n
        dist[idx] = d
        prim[idx] = face
        uv[idx] = cut.tri_uv[3 * face] * bu + cut.tri_uv[3 * face + 1] * bv + cut.tri_uv[3 * face + 2] * (1.0 - bu - bv)
        bary[idx] = wp.vec2(bu, bv)
        err[idx] = scale
    else:
        pos[idx] = wp.vec3(0.0)
        nrm[idx] = wp.vec3(0.0)
        dist[idx] = 0.0
        prim[idx] = -1
        uv[idx] = wp.vec2(0.0)
        bary[idx] = wp.vec2(0.0)
        err[idx] = 0.0


@wp.struct
class GBufferGPU:
    """The G-buffer on the device (see :class:`GBuffer` for the fields)."""

    width: int
    height: int
    spp: int
    grid: int
    pos: wp.array[wp.vec3]
    nrm: wp.array[wp.vec3]
    dist: wp.array[float]
    prim: wp.array[wp.int32]
    uv: wp.array[wp.vec2]
    bary: wp.array[wp.vec2]
    err: wp.array[float]


@wp.func
def gb_covered(gb: GBufferGPU, i: int) -> bool:
    """Does sample ``i`` lie on a surface (not the background)?"""
    return gb.prim[i] >= 0


@wp.func
def gb_layer(gb: GBufferGPU, i: int) -> int:
    """Which of its pixel's samples ``i`` is (0 .. spp-1)."""
    return i / (gb.width * gb.height)


@wp.func
def gb_pixel(gb: GBufferGPU, i: int) -> wp.vec2i:
    """The pixel (x, y) of sample ``i``; y = 0 is the top row."""
    p = i - gb_layer(gb, i) * gb.width * gb.height
    y = p / gb.width
    return wp.vec2i(p - y * gb.width, y)


@wp.func
def gb_index(gb: GBufferGPU, x: int, y: int, layer: int) -> int:
    """The sample of pixel (x, y) in ``layer``."""
    return (layer * gb.height + y) * gb.width + x


@wp.func
def gb_neighbour(gb: GBufferGPU, i: int, dx: int, dy: int) -> int:
    """The sample in ``i``'s layer at the pixel (dx, dy) away, or -1 outside the image (always -1
    in a bake G-buffer, whose samples are independent points)."""
    if gb.grid == 0:
        return -1
    p = gb_pixel(gb, i)
    x = p[0] + dx
    y = p[1] + dy
    if x < 0 or y < 0 or x >= gb.width or y >= gb.height:
        return -1
    return gb_index(gb, x, y, gb_layer(gb, i))


@wp.func
def gb_receiver(lv: ViewGPU, gb: GBufferGPU, i: int) -> wp.vec4:
    """Sample ``i`` seen from a light view: its view-space point (xyz) and w = 1, or w = 0 where
    nothing mapped can shadow it (the background, or behind a perspective light's near plane)."""
    if not gb_covered(gb, i):
        return wp.vec4(0.0)
    v = view_of(lv, gb.pos[i])
    if not in_front_of_light(lv, v):
        return wp.vec4(v[0], v[1], v[2], 0.0)
    return wp.vec4(v[0], v[1], v[2], 1.0)


@wp.func
def gb_mapped_receiver(lv: ViewGPU, gb: GBufferGPU, i: int):
    """Sample ``i`` as a technique that reads a light map at the receiver sees it: (mapped, its
    view-space point, its window coordinates, its continuous texel coordinates). ``mapped`` is false
    where nothing mapped can shadow it (the background, behind a perspective light's near plane,
    or outside the map): such a sample is lit."""
    r = gb_receiver(lv, gb, i)
    pv = wp.vec3(r[0], r[1], r[2])
    t = texel_of(lv, pv)
    return r[3] != 0.0 and inside_map(lv, t), pv, map_coords(lv, pv), t


@wp.func
def gb_mapped_depth(lv: ViewGPU, gb: GBufferGPU, i: int, bias: float):
    """:func:`gb_mapped_receiver` as a prefiltered map (``vsm``, ``esm``, ``msm``, ``evsm``) reads
    it: (mapped, the receiver's depth normalised over the view's near and far planes less ``bias``,
    its window coordinates)."""
    mapped, pv, m, t = gb_mapped_receiver(lv, gb, i)
    return mapped, normalised_depth(pv[2], lv.near, lv.far - lv.near) - bias, m


@dataclass
class GBuffer:
    """Eye-view samples, flat arrays of length ``spp*height*width`` (sample-major).

    ``pos``/``nrm`` vec3 world position and viewer-facing unit normal; ``dist`` float32 camera
    distance; ``prim`` int32 triangle index (-1 = background); ``uv`` vec2 texture coordinates;
    ``bary`` vec2 weights (u, v) of the triangle's first two corners (the third is 1 - u - v);
    ``err`` float32 the scale the sample's rounding is a few ulps of (the largest coordinate of its
    triangle's corners, :func:`~wsoft.scene.offsets.triangle_scale`; a bake's given points: the
    largest coordinate of them all; None: each point's own), which sets how far its shadow rays
    start off the surface (:func:`~wsoft.raster.shadow_rays.receiver_begin`).
    ``grid``: True for an image (neighbouring samples are neighbouring pixels), False for a bake
    G-buffer of independent points (:func:`bake_gbuffer`).
    """

    width: int
    height: int
    spp: int
    pos: wp.array
    nrm: wp.array
    dist: wp.array
    prim: wp.array
    uv: wp.array
    bary: wp.array
    grid: bool = True
    err: wp.array | None = None
    _bounds: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def count(self) -> int:
        return self.width * self.height * self.spp

    def receiver_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) of the covered samples' positions (float64, exactly the float32 extremes), or
        None when nothing is covered: reduced on the device in disjoint chunks, computed once."""
        if self._bounds is None:
            n = self.count
            chunks = max(1, min(256, (n + 4095) // 4096))
            dev = self.pos.device
            lo = wp.empty(chunks, dtype=wp.vec3, device=dev)
            hi = wp.empty(chunks, dtype=wp.vec3, device=dev)
            found = wp.empty(chunks, dtype=wp.int32, device=dev)
            launch_chunked(reduce_receiver_bounds, chunks, inputs=[n, chunks, self.pos, self.prim], outputs=[lo, hi, found],
                           device=str(dev), min_chunk=1)
            f = found.numpy() > 0
            self._bounds = (lo.numpy()[f].astype(np.float64).min(axis=0), hi.numpy()[f].astype(np.float64).max(axis=0)) if f.any() else ()
        return self._bounds or None

    def arrays(self) -> dict[str, wp.array]:
        a = {"pos": self.pos, "nrm": self.nrm, "dist": self.dist, "prim": self.prim, "uv": self.uv, "bary": self.bary}
        if self.err is not None:
            a["err"] = self.err
        return a

    def gpu(self) -> GBufferGPU:
        g = GBufferGPU()
        g.width, g.height, g.spp, g.grid = self.width, self.height, self.spp, int(self.grid)
        g.pos, g.nrm, g.dist, g.prim, g.uv, g.bary = self.pos, self.nrm, self.dist, self.prim, self.uv, self.bary
        if self.err is None:
            self.err = wp.zeros(self.count, dtype=float, device=self.pos.device)
        g.err = self.err
        return g

    def host(self, name: str) -> np.ndarray:
        """A field as numpy, shape [spp, H, W(, C)]."""
        a = getattr(self, name).numpy()
        return a.reshape((self.spp, self.height, self.width) + a.shape[1:])


@wp.kernel
def reduce_receiver_bounds(
    offset: int,
    n: int,
    chunks: int,
    pos: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    # outputs
    lo: wp.array[wp.vec3],
    hi: wp.array[wp.vec3],
    found: wp.array[wp.int32],
):
    """Chunk ``c`` of the samples: the bounds of its covered positions (each chunk its own slot)."""
    c = wp.tid() + offset
    step = (n + chunks - 1) // chunks
    a = wp.vec3(1.0e38)
    b = wp.vec3(-1.0e38)
    any_covered = int(0)
    for i in range(c * step, wp.min(n, (c + 1) * step)):
        if prim[i] >= 0:
            p = pos[i]
            a = wp.min(a, p)
            b = wp.max(b, p)
            any_covered = 1
    lo[c] = a
    hi[c] = b
    found[c] = any_covered


def render_gbuffer(ds: DeviceScene, cam: CameraGPU, width: int, height: int, spp: int, alpha_tested: bool) -> GBuffer:
    n = width * height * spp
    dev = ds.device
    g = GBuffer(
        width,
        height,
        spp,
        pos=wp.empty(n, dtype=wp.vec3, device=dev),
        nrm=wp.empty(n, dtype=wp.vec3, device=dev),
        dist=wp.empty(n, dtype=float, device=dev),
        prim=wp.empty(n, dtype=wp.int32, device=dev),
        uv=wp.empty(n, dtype=wp.vec2, device=dev),
        bary=wp.empty(n, dtype=wp.vec2, device=dev),
        err=wp.empty(n, dtype=float, device=dev),
    )
    launch_chunked(
        trace_gbuffer,
        n,
        inputs=[ds.mesh.id, ds.cutouts, int(alpha_tested and ds.has_cutouts), ds.inst, cam, width, height, spp],
        outputs=[g.pos, g.nrm, g.dist, g.prim, g.uv, g.bary, g.err],
        device=dev,
    )
    return g


def bake_gbuffer(pos: np.ndarray, nrm: np.ndarray, prim: np.ndarray, uv: np.ndarray | None, device: str) -> GBuffer:
    """A G-buffer whose samples are given points (a bake, :mod:`wsoft.baking`) instead of camera-ray
    hits: ``pos`` [N, 3] world points, ``nrm`` [N, 3] unit normals (the side whose visibility is
    wanted), ``prim`` [N] the triangle each lies on (>= 0), ``uv`` [N, 2] or None (zeros).

    The N points are packed row by row into a near-square ``W x H`` image of one layer (W = ceil
    sqrt N), the last row padded with background samples (``prim = -1``, visibility 1), so that
    the per-pixel light-sample patterns (``interleave``, ``rotate``) still vary over two axes;
    ``grid = False``: no sample is another's neighbour; ``err``: the largest coordinate of the
    points (no triangle's corners are at hand). ``dist`` (camera distance) and ``bary``
    are 0: a bake has no camera, and no technique that bakes reads them."""
    n = int(len(pos))
    w = max(1, int(np.ceil(np.sqrt(max(n, 1)))))
    h = max(1, (n + w - 1) // w)
    total = w * h

    def padded(a, width, fill):
        out = np.full((total, width) if width else total, fill, dtype=np.float32 if width else np.int32)
        if n:
            out[:n] = a
        return out

    return GBuffer(
        w, h, 1,
        pos=wp.array(padded(np.asarray(pos, np.float32), 3, 0.0), dtype=wp.vec3, device=device),
        nrm=wp.array(padded(np.asarray(nrm, np.float32), 3, 0.0), dtype=wp.vec3, device=device),
        dist=wp.zeros(total, dtype=float, device=device),
        prim=wp.array(padded(np.asarray(prim, np.int32), 0, -1), dtype=wp.int32, device=device),
        uv=wp.array(padded(np.zeros((n, 2), np.float32) if uv is None else np.asarray(uv, np.float32), 2, 0.0), dtype=wp.vec2, device=device),
        bary=wp.zeros(total, dtype=wp.vec2, device=device),
        grid=False,
        err=wp.full(total, float(np.abs(np.asarray(pos, np.float32)).max(initial=0.0)), dtype=float, device=device),
    )
