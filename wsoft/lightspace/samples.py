"""Light samples: the one generator of sample patterns over a light.

Every technique that samples the light uses it: the ray-traced reference, the filter taps of
PCF/PCSS, backprojection's occlusion bitmasks, depth-complexity sampling. A
:class:`SamplePattern` says which points; points live in the unit square ``[0, 1)^2`` and are
mapped onto the light's shape by :func:`to_light_coords` (``2u - 1`` on a rectangle, the
Shirley-Chiu concentric map on a disk, :func:`concentric_disk`), giving *light coordinates* in
``[-1, 1]^2`` or the unit disk.

Kinds:

* ``regular`` — centres of an ``m x m`` grid (``count = m^2``, row-major: sample ``r m + c`` in
  cell ``(c, r)``); other counts: a rank-1 (Fibonacci) lattice.
* ``jittered`` — one uniform point in each cell of that grid (square counts).
* ``random`` — independent uniform points.
* ``stratified`` — a jittered grid for square counts, else a randomly shifted rank-1 lattice.
* ``poisson`` — dart throwing in the square with a minimum distance ``min_distance`` (unit-square
  units; Forest et al. fix 0.2456139 for 16 and 0.1076681 for 64 samples,
  :data:`PAPER_MIN_DISTANCE`; slightly denser near the edges, see :func:`poisson_disk`).
  ``min_distance = 0`` (the filter taps) starts at ``0.8/sqrt(count)`` and shrinks by 0.9 until
  every point fits.
* ``sobol02`` — the first ``count`` points of the (0, 2)-sequence in base 2 (Sobol's first two
  dimensions), scrambled by a random digital shift per set: the first ``2^m`` points put exactly
  one point in every elementary interval of area ``2^-m``.

Decorrelation between pixels:

* ``per_pixel`` — a new set for every pixel, generated on the device (``regular``, ``jittered``,
  ``random``, ``stratified``): the reference's sampling. Draws are counter-based: coordinate
  ``dim`` of sample ``s`` of receiver ``index`` is a hash of (seed, index, s, dim)
  (:func:`counter_draw`, nested PCG hashes, :func:`pcg_hash`), so a packet's rays are generated
  side by side, none waiting on another's draw. ``jittered`` and ``stratified`` at a square count
  ``m^2``: sample ``s`` in stratum ``(s mod m, s div m)``, jittered by its dimensions 0 and 1;
  ``stratified`` at other counts: the rank-1 lattice shifted toroidally by the receiver's
  dimensions 2 and 3 of sample 0 (one shift per receiver); ``random``: dimensions 0 and 1.
  ``rtdenoise``, and ``dcs`` and ``pwedge`` with ``decorrelate=per_pixel``, draw the same way,
  through :func:`sampling_begin` and :func:`sample_coords`.
* ``rotate`` — the precomputed set turned per pixel by a random angle about the light's centre
  (a disk light) or, on a rectangle where a turned set would leave the light, shifted by a random
  toroidal offset (the Cranley-Patterson rotation, the square's uniformity-preserving analogue).
* ``interleave = n`` — ``n x n`` independent precomputed sets; pixel ``(x, y)`` uses set
  ``(x mod n) + n (y mod n)`` (interleaved sampling).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked

KINDS = ("regular", "jittered", "random", "stratified", "poisson", "sobol02")
KIND_REGULAR, KIND_JITTERED, KIND_RANDOM, KIND_STRATIFIED, KIND_POISSON, KIND_SOBOL02 = range(6)
DEVICE_KINDS = ("regular", "jittered", "random", "stratified")  # can be generated per pixel on the device
PAPER_MIN_DISTANCE = {16: 0.2456139, 64: 0.1076681}  # Forest et al. 2009, Poisson-disk minimum distances
GOLDEN = 0.6180339887498949  # the rank-1 lattice's generator (golden ratio conjugate)
ROTATION_SALT = wp.constant(0x2545F491)  # seeds the per-pixel rotation stream apart from the sampling stream
PCG_INCREMENT = wp.constant(wp.uint32(2891336453))  # pcg_hash's LCG increment (above the int32 range)


@wp.func
def concentric_disk(u1: float, u2: float) -> wp.vec2:
    """Shirley-Chiu concentric map of [0,1)^2 onto the unit disk (keeps strata compact)."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return wp.vec2(0.0, 0.0)
    r = float(0.0)
    phi = float(0.0)
    if wp.abs(a) > wp.abs(b):
        r = a
        phi = (wp.pi / 4.0) * (b / a)
    else:
        r = b
        phi = (wp.pi / 2.0) - (wp.pi / 4.0) * (a / b)
    return wp.vec2(r * wp.cos(phi), r * wp.sin(phi))


@wp.func
def to_light_coords(u: wp.vec2, disk: int) -> wp.vec2:
    """Unit-square point -> light coordinates: ``2u - 1`` on a rectangle, the concentric map on a disk."""
    if disk != 0:
        return concentric_disk(u[0], u[1])
    return wp.vec2(2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0)


@wp.func
def stratified_sample(s: int, n: int, m: int, jitter: wp.vec2, shift: wp.vec2) -> wp.vec2:
    """Sample ``s`` of ``n``: jittered m x m grid when m*m == n, else a shifted rank-1 lattice.

    ``jitter`` is the offset inside the grid stratum (0.5, 0.5 = its centre); ``shift`` the
    lattice's random shift."""
    if m * m == n:
        if (m & (m - 1)) == 0:
            # m a power of two: the stratum by mask and shift, and the division by m a multiplication by
            # 1/m (both exact scalings by a power of two: the same bits), so no divider work per sample
            inv = 1.0 / float(m)
            return wp.vec2((float(s & (m - 1)) + jitter[0]) * inv, (float(s >> wp.bit_count(wp.uint32(m - 1))) + jitter[1]) * inv)
        gx = s % m
        gy = s // m
        return wp.vec2((float(gx) + jitter[0]) / float(m), (float(gy) + jitter[1]) / float(m))
    x = (float(s) + 0.5) / float(n) + shift[0]
    y = float(s) * 0.6180339887498949 + 0.5 / float(n) + shift[1]
    return wp.vec2(x - wp.floor(x), y - wp.floor(y))


@wp.struct
class LightSamples:
    """A :class:`SamplePattern` on the device. ``table``: the precomputed sets, ``sets * count``
    unit-square points (one dummy point for per-pixel kinds)."""

    table: wp.array[wp.vec2]
    count: int
    grid: int  # m when count == m * m, else 0
    kind: int
    per_pixel: int
    rotate: int
    interleave: int
    seed: int
    disk: int  # map onto the unit disk


@wp.func
def pcg_hash(v: wp.uint32) -> wp.uint32:
    """The PCG-RXS-M-XS permutation of a 32-bit word (Jarzynski and Olano 2020, "Hash functions
    for GPU rendering"): one LCG step, then an output permutation."""
    state = v * wp.uint32(747796405) + PCG_INCREMENT
    word = ((state >> ((state >> wp.uint32(28)) + wp.uint32(4))) ^ state) * wp.uint32(277803737)
    return (word >> wp.uint32(22)) ^ word


@wp.func
def pixel_key(seed: int, index: int) -> wp.uint32:
    """A receiver's key for its counter-based draws: the hash of (``seed``, ``index``)."""
    return pcg_hash(pcg_hash(wp.uint32(seed)) + wp.uint32(index))


@wp.func
def counter_draw(key: wp.uint32, s: int, dim: int) -> float:
    """Dimension ``dim`` of sample ``s`` of the receiver with ``key`` (:func:`pixel_key`): a uniform
    float in [0, 1) (24 bits) from the nested hash of (key, s, dim), depending on no other draw."""
    h = pcg_hash(pcg_hash(key + wp.uint32(s)) + wp.uint32(dim))
    return float(h >> wp.uint32(8)) * (1.0 / 16777216.0)


@wp.func
def counter_pair(key: wp.uint32, s: int, dim: int) -> wp.vec2:
    """Dimensions ``dim`` and ``dim + 1`` of sample ``s`` (:func:`counter_draw` of each, the same
    bits), the hash of (key, s) they share computed once."""
    ks = pcg_hash(key + wp.uint32(s))
    h0 = pcg_hash(ks + wp.uint32(dim))
    h1 = pcg_hash(ks + wp.uint32(dim + 1))
    return wp.vec2(float(h0 >> wp.uint32(8)) * (1.0 / 16777216.0), float(h1 >> wp.uint32(8)) * (1.0 / 16777216.0))


@wp.func
def sampling_begin(ls: LightSamples, index: int, px: int, py: int):
    """Start a pixel's samples: (its key or random state, first table index, rotation (cos, sin,
    dx, dy)). ``index``: the receiver's own index (seeds its draws); ``px, py``: its pixel
    (interleaving). Per-pixel sets: the key of :func:`counter_draw`, and for ``stratified`` the
    lattice's shift (dimensions 2 and 3 of sample 0)."""
    rot = wp.vec4(1.0, 0.0, 0.0, 0.0)
    base = int(0)
    if ls.per_pixel != 0:
        key = pixel_key(ls.seed, index)
        if ls.kind == 3:  # stratified
            rot = wp.vec4(1.0, 0.0, counter_draw(key, 0, 2), counter_draw(key, 0, 3))
        return key, base, rot
    state = wp.rand_init(ls.seed, index)
    n = ls.interleave
    base = ((py % n) * n + (px % n)) * ls.count
    if ls.rotate != 0:
        rs = wp.rand_init(ls.seed ^ ROTATION_SALT, index)
        if ls.disk != 0:
            a = 2.0 * wp.pi * wp.randf(rs)
            rot = wp.vec4(wp.cos(a), wp.sin(a), 0.0, 0.0)
        else:
            dx = wp.randf(rs)
            dy = wp.randf(rs)
            rot = wp.vec4(1.0, 0.0, dx, dy)
    return state, base, rot


@wp.func
def sample_coords(ls: LightSamples, state: wp.uint32, base: int, rot: wp.vec4, s: int):
    """Light coordinates of sample ``s`` of a pixel started by :func:`sampling_begin`, and
    ``state`` passed on unchanged: per-pixel sets draw sample ``s`` from the pixel's key and ``s``
    alone (dimensions 0 and 1 of :func:`counter_draw`, through :func:`counter_pair`), so any sample is
    computed without the others."""
    u = wp.vec2(0.0, 0.0)
    if ls.per_pixel != 0:
        if ls.kind == 0:  # regular
            u = stratified_sample(s, ls.count, ls.grid, wp.vec2(0.5, 0.5), wp.vec2(0.0, 0.0))
        else:  # random; jittered and stratified (jitter in the stratum, or the lattice's shift in rot)
            ab = counter_pair(state, s, 0)
            if ls.kind == 2:
                u = ab
            else:
                u = stratified_sample(s, ls.count, ls.grid, ab, wp.vec2(rot[2], rot[3]))
        return to_light_coords(u, ls.disk), state
    u = ls.table[base + s]
    if ls.rotate != 0 and ls.disk == 0:
        x = u[0] + rot[2]
        y = u[1] + rot[3]
        u = wp.vec2(x - wp.floor(x), y - wp.floor(y))
    c = to_light_coords(u, ls.disk)
    if ls.rotate != 0 and ls.disk != 0:
        c = wp.vec2(rot[0] * c[0] - rot[1] * c[1], rot[1] * c[0] + rot[0] * c[1])
    return c, state


@wp.kernel
def map_to_light(
    offset: int,
    table: wp.array[wp.vec2],
    disk: int,
    # outputs
    out: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    out[i] = to_light_coords(table[i], disk)


@dataclass(frozen=True)
class SamplePattern:
    """Which points over the light (see the module docstring)."""

    kind: str = "stratified"
    count: int = 16
    seed: int = 0
    min_distance: float = 0.0  # poisson: unit-square units (0: shrink from 0.8/sqrt(count))
    per_pixel: bool = False  # a new set per pixel, generated on the device
    rotate: bool = False  # per-pixel random rotation of the precomputed set
    interleave: int = 1  # n x n interleaved precomputed sets

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"sample pattern {self.kind!r} is not one of {', '.join(KINDS)}")
        if not 1 <= self.count <= 1 << 20:
            raise ValueError(f"sample count {self.count} out of range [1, 1048576]")
        if self.kind == "jittered" and math.isqrt(self.count) ** 2 != self.count:
            raise ValueError(f"the jittered pattern needs a square sample count, not {self.count}")
        if not (0.0 <= self.min_distance < 1.0) or math.isnan(self.min_distance):
            raise ValueError(f"min_distance {self.min_distance} must be in [0, 1)")
        if self.per_pixel and self.kind not in DEVICE_KINDS:
            raise ValueError(f"per-pixel sets are generated on the device for {', '.join(DEVICE_KINDS)} only, not {self.kind}")
        if self.per_pixel and (self.rotate or self.interleave != 1):
            raise ValueError("per-pixel sets are already decorrelated: no rotation or interleaving")
        if not 1 <= self.interleave <= 16:
            raise ValueError(f"interleave {self.interleave} out of range [1, 16]")

    @property
    def grid(self) -> int:
        m = math.isqrt(self.count)
        return m if m * m == self.count else 0

    @property
    def sets(self) -> int:
        return self.interleave * self.interleave

    # -- host generation -------------------------------------------------------------------------
    def points(self) -> np.ndarray:
        """The precomputed sets, ``[sets, count, 2]`` float64 unit-square points (set ``k`` from
        ``seed`` for k = 0, else from ``(seed, k)``). Generated once per pattern (Poisson-disk dart
        throwing costs up to a second for 16 interleaved sets) and read-only."""
        return _pattern_points(self)

    def _one_set(self, rng: np.random.Generator) -> np.ndarray:
        n, m = self.count, self.grid
        if self.kind == "regular":
            if m:
                c, r = np.meshgrid(np.arange(m), np.arange(m))
                return np.stack([((c + 0.5) / m).ravel(), ((r + 0.5) / m).ravel()], -1)
            return rank1_lattice(n, (0.0, 0.0))
        if self.kind == "jittered" or (self.kind == "stratified" and m):
            c, r = np.meshgrid(np.arange(m), np.arange(m))
            u = (c + rng.random((m, m))) / m
            v = (r + rng.random((m, m))) / m
            return np.stack([u.ravel(), v.ravel()], -1)
        if self.kind == "stratified":
            return rank1_lattice(n, tuple(rng.random(2)))
        if self.kind == "random":
            u = rng.random(n)
            v = rng.random(n)
            return np.stack([u, v], -1)
        if self.kind == "poisson":
            return poisson_disk(n, self.min_distance, rng)
        return sobol02(n, rng)

    # -- device ------------------------------------------------------------------------------------
    def on(self, device: str, disk: bool) -> LightSamples:
        """The pattern on ``device``, mapped onto a disk (``disk``) or a rectangle."""
        ls = LightSamples()
        if self.per_pixel:
            ls.table = wp.zeros(1, dtype=wp.vec2, device=device)
        else:
            ls.table = wp.array(self.points().reshape(-1, 2).astype(np.float32), dtype=wp.vec2, device=device)
        ls.count = self.count
        ls.grid = self.grid
        ls.kind = KINDS.index(self.kind)
        ls.per_pixel = int(self.per_pixel)
        ls.rotate = int(self.rotate)
        ls.interleave = self.interleave
        ls.seed = int(self.seed)
        ls.disk = int(disk)
        return ls

    def light_coords(self, device: str, disk: bool) -> wp.array:
        """Every precomputed set in light coordinates (``[sets * count]`` vec2 on ``device``),
        mapped by the device's :func:`to_light_coords`."""
        if self.per_pixel:
            raise ValueError("per-pixel sets have no table")
        table = wp.array(self.points().reshape(-1, 2).astype(np.float32), dtype=wp.vec2, device=device)
        out = wp.empty_like(table)
        launch_chunked(map_to_light, table.shape[0], inputs=[table, int(disk)], outputs=[out], device=device)
        return out

DECORRELATIONS = ("rotate", "interleave", "per_pixel", "none")


def check_decorrelation(pattern: str, samples: int, decorrelate: str) -> str | None:
    """Why a (pattern, samples, decorrelate) choice of the object-based techniques' parameters is
    invalid, or None."""
    if pattern not in KINDS:
        return f"pattern {pattern!r} is not one of {', '.join(KINDS)}"
    if decorrelate not in DECORRELATIONS:
        return f"decorrelate {decorrelate!r} is not one of {', '.join(DECORRELATIONS)}"
    if decorrelate == "per_pixel" and pattern not in DEVICE_KINDS:
        return f"decorrelate=per_pixel needs a pattern generated on the device ({', '.join(DEVICE_KINDS)}), not {pattern}"
    if pattern == "jittered" and math.isqrt(samples) ** 2 != samples:
        return f"pattern=jittered needs a square sample count, not {samples}"
    return None


def paper_pattern(pattern: str, samples: int, seed: int, decorrelate: str, interleave: int) -> SamplePattern:
    """The light samples of Forest et al.'s techniques (``dcs``, ``pwedge``): ``pattern`` with the
    paper's Poisson-disk minimum distances at 16 and 64 samples, decorrelated between pixels by a
    per-pixel rotation, ``interleave`` x ``interleave`` interleaved sets, a new set per pixel, or
    not at all."""
    return SamplePattern(pattern, samples, seed=seed,
                         min_distance=PAPER_MIN_DISTANCE.get(samples, 0.0) if pattern == "poisson" else 0.0,
                         per_pixel=decorrelate == "per_pixel", rotate=decorrelate == "rotate",
                         interleave=interleave if decorrelate == "interleave" else 1)



@functools.lru_cache(maxsize=64)
def _pattern_points(pattern: SamplePattern) -> np.ndarray:
    pts = np.stack([pattern._one_set(np.random.default_rng(pattern.seed if k == 0 else (pattern.seed, k))) for k in range(pattern.sets)])
    pts.setflags(write=False)
    return pts


def rank1_lattice(n: int, shift: tuple[float, float]) -> np.ndarray:
    """``n`` points of the Fibonacci rank-1 lattice ``((s + 0.5)/n, s phi + 0.5/n)`` shifted
    toroidally by ``shift``."""
    s = np.arange(n, dtype=np.float64)
    x = (s + 0.5) / n + shift[0]
    y = s * GOLDEN + 0.5 / n + shift[1]
    return np.stack([x - np.floor(x), y - np.floor(y)], -1)


def poisson_disk(n: int, min_distance: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` unit-square points no two closer than ``min_distance`` (dart throwing in the square;
    up to 64 restarts, then ``ValueError``). ``min_distance = 0``: the filter taps' pattern,
    starting at ``0.8/sqrt(n)`` and shrinking the radius by 0.9 whenever 2000 darts in a row miss.

    Points near the square's edges have fewer neighbours to keep away from, so the sets are slightly
    denser there (on a disk light 19-23% of the samples fall within half the radius instead of 25%,
    depending on count and distance; tests/test_samples.py). Forest et al.'s distances need that room: on the torus
    (no edge, uniform density) 16 points at 0.2456 and 64 at 0.1077 exceed what dart throwing can pack."""
    if min_distance <= 0.0:
        # thrown in [-1, 1]^2 at twice the radius: the filter taps' historical stream
        r = 1.6 / math.sqrt(n)
        pts: list[np.ndarray] = []
        while len(pts) < n:
            for _ in range(2000):
                c = rng.uniform(-1.0, 1.0, 2)
                if all(np.hypot(*(c - q)) >= r for q in pts):
                    pts.append(c)
                    if len(pts) == n:
                        break
            r *= 0.9
        return (np.asarray(pts) + 1.0) * 0.5
    d2 = min_distance * min_distance
    for _ in range(64):
        pts_a = np.empty((n, 2))
        k = 0
        misses = 0
        while k < n and misses < 200 * n:
            cand = rng.random((256, 2))
            # darts too near a point placed before this batch, in one go; then one by one in order
            # against the points this batch places (the same test, the same decisions)
            k0 = k
            near = (np.sum((cand[:, None, :] - pts_a[None, :k0]) ** 2, axis=2) < d2).any(axis=1) if k0 else np.zeros(len(cand), bool)
            for c, too_near in zip(cand, near):
                if too_near or (k > k0 and np.min(np.sum((pts_a[k0:k] - c) ** 2, axis=1)) < d2):
                    misses += 1
                    continue
                pts_a[k] = c
                k += 1
                if k == n:
                    break
        if k == n:
            return pts_a
    raise ValueError(f"cannot place {n} Poisson-disk samples at minimum distance {min_distance}")


def sobol02(n: int, rng: np.random.Generator) -> np.ndarray:
    """The first ``n`` points of the (0, 2)-sequence in base 2 (van der Corput and Sobol's second
    dimension, whose generator matrix is Pascal's triangle mod 2), with a random digital shift
    (an XOR of each coordinate's 32 bits), which keeps the net property."""
    bits = 32
    idx = np.arange(n, dtype=np.uint64)
    x = np.zeros(n, np.uint64)
    y = np.zeros(n, np.uint64)
    # column j of the generator matrices maps digit j of the index (LSB first) to output bits
    for j in range(bits):
        a = (idx >> np.uint64(j)) & np.uint64(1)
        if not a.any():
            break
        x ^= a << np.uint64(bits - 1 - j)  # van der Corput: digit j -> bit j after the point
        col = 0
        for k in range(j + 1):  # Pascal: output digit k gets C(j, k) mod 2 of digit j
            if math.comb(j, k) & 1:
                col |= 1 << (bits - 1 - k)
        y ^= a * np.uint64(col)
    sx, sy = (int(v) for v in rng.integers(0, 1 << bits, 2, dtype=np.uint64))
    x ^= np.uint64(sx)
    y ^= np.uint64(sy)
    scale = 1.0 / float(1 << bits)
    return np.stack([x.astype(np.float64) * scale, y.astype(np.float64) * scale], -1)
