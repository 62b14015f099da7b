"""Occlusion bitmasks over light samples: which of a pixel's ``n x n`` light samples are blocked.

A mask holds up to 32 x 32 samples (:data:`MASK_WORDS` words of 32 bits; a row of ``n`` samples
never straddles a word since ``n`` divides 32). Samples are light coordinates (``[-1, 1]^2`` or
the unit disk, :mod:`wsoft.lightspace.samples`) laid out row-major; ``pattern`` tells the fill
functions how much of that layout they may rely on:

* ``PATTERN_REGULAR`` — sample ``r n + c`` at the centre of cell ``(c, r)`` of the square;
* ``PATTERN_JITTERED`` — sample ``r n + c`` somewhere inside cell ``(c, r)``;
* ``PATTERN_ANY`` — anything (random, Poisson, low-discrepancy, or mapped onto a disk): every
  sample is tested.

:func:`mask_rect` and :func:`mask_quad` OR the samples a backprojected occluder covers into a
mask; :func:`popcount` / :func:`mask_visibility` count them.
"""

from __future__ import annotations

import warp as wp

PATTERN_REGULAR = wp.constant(0)
PATTERN_JITTERED = wp.constant(1)
PATTERN_ANY = wp.constant(2)  # random, or any pattern mapped into a disk: every sample is tested

MASK_WORDS = 32  # room for 32 x 32 light samples
mask_t = wp.types.vector(length=MASK_WORDS, dtype=wp.uint32)



@wp.func
def popcount(v: wp.uint32) -> int:
    x = v - ((v >> wp.uint32(1)) & wp.uint32(0x55555555))
    x = (x & wp.uint32(0x33333333)) + ((x >> wp.uint32(2)) & wp.uint32(0x33333333))
    x = (x + (x >> wp.uint32(4))) & wp.uint32(0x0F0F0F0F)
    return int((x * wp.uint32(0x01010101)) >> wp.uint32(24))


@wp.func
def set_bit(m: mask_t, b: int) -> mask_t:
    w = b >> 5
    m[w] = m[w] | (wp.uint32(1) << wp.uint32(b & 31))
    return m


@wp.func
def set_run(m: mask_t, n: int, row: int, c0: int, c1: int) -> mask_t:
    """Set the bits of columns c0..c1 (inclusive) of a row (rows never straddle words: n | 32)."""
    if c0 > c1:
        return m
    b = row * n + c0
    w = b >> 5
    run = wp.uint32((wp.uint64(1) << wp.uint64(c1 - c0 + 1)) - wp.uint64(1))
    bits = run << wp.uint32(b & 31)
    m[w] = m[w] | bits
    return m


@wp.func
def mask_rect(m: mask_t, n: int, pattern: int, samples: wp.array[wp.vec2], lo: wp.vec2, hi: wp.vec2) -> mask_t:
    """Mark the light samples (``n x n``, laid out as ``pattern`` says) inside the light-coordinate
    rectangle [lo, hi]. Grid patterns visit only the cells the rectangle overlaps."""
    fn = float(n)
    if pattern == PATTERN_REGULAR:
        c0 = wp.max(int(wp.ceil((lo[0] + 1.0) * 0.5 * fn - 0.5)), 0)
        c1 = wp.min(int(wp.ceil((hi[0] + 1.0) * 0.5 * fn - 0.5)) - 1, n - 1)
        r0 = wp.max(int(wp.ceil((lo[1] + 1.0) * 0.5 * fn - 0.5)), 0)
        r1 = wp.min(int(wp.ceil((hi[1] + 1.0) * 0.5 * fn - 0.5)) - 1, n - 1)
        for r in range(r0, r1 + 1):
            m = set_run(m, n, r, c0, c1)
        return m
    if pattern == PATTERN_JITTERED:
        c0 = wp.max(int(wp.floor((lo[0] + 1.0) * 0.5 * fn)), 0)
        c1 = wp.min(int(wp.floor((hi[0] + 1.0) * 0.5 * fn)), n - 1)
        r0 = wp.max(int(wp.floor((lo[1] + 1.0) * 0.5 * fn)), 0)
        r1 = wp.min(int(wp.floor((hi[1] + 1.0) * 0.5 * fn)), n - 1)
        for r in range(r0, r1 + 1):
            if r > r0 and r < r1:
                m = set_run(m, n, r, c0 + 1, c1 - 1)  # cells wholly inside
                for c in range(c0, c1 + 1, wp.max(c1 - c0, 1)):
                    q = samples[r * n + c]
                    if q[0] >= lo[0] and q[0] < hi[0]:
                        m = set_bit(m, r * n + c)
            else:
                for c in range(c0, c1 + 1):
                    q = samples[r * n + c]
                    if q[0] >= lo[0] and q[0] < hi[0] and q[1] >= lo[1] and q[1] < hi[1]:
                        m = set_bit(m, r * n + c)
        return m
    for b in range(n * n):
        q = samples[b]
        if q[0] >= lo[0] and q[0] < hi[0] and q[1] >= lo[1] and q[1] < hi[1]:
            m = set_bit(m, b)
    return m


@wp.func
def mask_behind(m: mask_t, n: int, samples: wp.array[wp.vec2], h: wp.vec3) -> mask_t:
    """Mark the light samples behind the line ``h`` (``h . (x, y, 1) < 0``: behind a receiver's
    tangent plane, :mod:`wsoft.lightspace.halfspace`): they cannot light it."""
    for b in range(n * n):
        q = samples[b]
        if h[0] * q[0] + h[1] * q[1] + h[2] < 0.0:
            m = set_bit(m, b)
    return m


@wp.func
def edge_side(a: wp.vec2, b: wp.vec2, p: wp.vec2) -> float:
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])


@wp.func
def in_triangle(a: wp.vec2, b: wp.vec2, c: wp.vec2, p: wp.vec2) -> bool:
    e0 = edge_side(a, b, p)
    e1 = edge_side(b, c, p)
    e2 = edge_side(c, a, p)
    return (e0 >= 0.0 and e1 >= 0.0 and e2 >= 0.0) or (e0 <= 0.0 and e1 <= 0.0 and e2 <= 0.0)


@wp.func
def mask_quad(m: mask_t, n: int, pattern: int, samples: wp.array[wp.vec2], a: wp.vec2, b: wp.vec2, c: wp.vec2, d: wp.vec2) -> mask_t:
    """Mark the light samples inside the quadrilateral a b c d (two triangles a b c, a c d)."""
    fn = float(n)
    lo = wp.min(wp.min(a, b), wp.min(c, d))
    hi = wp.max(wp.max(a, b), wp.max(c, d))
    c0 = int(0)
    c1 = n - 1
    r0 = int(0)
    r1 = n - 1
    if pattern != PATTERN_ANY:
        c0 = wp.max(int(wp.floor((lo[0] + 1.0) * 0.5 * fn)), 0)
        c1 = wp.min(int(wp.floor((hi[0] + 1.0) * 0.5 * fn)), n - 1)
        r0 = wp.max(int(wp.floor((lo[1] + 1.0) * 0.5 * fn)), 0)
        r1 = wp.min(int(wp.floor((hi[1] + 1.0) * 0.5 * fn)), n - 1)
    for r in range(r0, r1 + 1):
        for cc in range(c0, c1 + 1):
            q = samples[r * n + cc]
            if in_triangle(a, b, c, q) or in_triangle(a, c, d, q):
                m = set_bit(m, r * n + cc)
    return m


@wp.func
def mask_visibility(m: mask_t, n: int) -> float:
    words = (n * n + 31) // 32
    hits = int(0)
    for w in range(words):
        hits += popcount(m[w])
    return 1.0 - float(hits) / float(n * n)
