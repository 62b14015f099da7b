"""What the reference's ray generation costs, apart from tracing: the packet pass's kernel
(:func:`~wsoft.reference.trace_visibility_packets`) with its tracing left out, and its random
draws alone.

* :func:`generate_packets` builds every receiver's packets with the pass's own
  :func:`~wsoft.reference.packet_rays` (the stratified sample, the light point and its direction,
  the test against the receiver's plane and the light's side) and traces none.
* :func:`random_draws` makes only the pass's random draws: per receiver the key from
  :func:`~wsoft.lightspace.samples.sampling_begin`, two counter-based draws a sample
  (:func:`~wsoft.lightspace.samples.counter_draw`: each a hash of the key, the sample and the
  dimension, none depending on another).

* :func:`covered_receivers` reads each receiver's G-buffer point and writes one value: what a
  chunked launch over the frame's receivers costs on Warp's CPU backend before any ray.

``bench foundation``'s ``ray_throughput`` rows time all three beside the pass (one thread): the
pass less the first is what tracing costs inside the pass; the second is the floor under any
generation that keeps the reference's samples, bit for bit; the third the floor under any pass.
"""

from __future__ import annotations

import warp as wp

import wsoft.parallel  # noqa: F401  (Warp configured before the kernels are defined)
from wsoft.lightspace.bitmask import popcount
from wsoft.lightspace.light import LightGPU
from wsoft.lightspace.samples import LightSamples, counter_draw, sampling_begin
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_pixel
from wsoft.raster.shadow_rays import receiver_begin
from wsoft.reference import packet_rays, visible_fraction
from wsoft.reference.packets import PACKET


@wp.kernel
def generate_packets(
    offset: int,
    light: LightGPU,
    ls: LightSamples,
    gb: GBufferGPU,
    dmax: float,
    # outputs
    vis: wp.array[float],
):
    """The packet pass's rays, generated and not traced (V: the fraction of them its plane and the
    light's side let through, plus a sum of the rays that keeps their computation)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    off, o, state, base, rot = receiver_begin(gb, ls, i)
    visible = int(0)
    keep = float(0.0)
    first = int(0)
    while first < ls.count:
        dx, dy, dz, tm, mask, state = packet_rays(light, ls, state, base, rot, p, n, off, dmax, first)
        for k in range(PACKET):
            keep += dx[k] + dy[k] + dz[k] + tm[k]
        visible += popcount(mask)
        first += PACKET
    v, e = visible_fraction(visible, ls.count)
    vis[i] = v + keep * 1.0e-30


@wp.kernel
def random_draws(
    offset: int,
    ls: LightSamples,
    gb: GBufferGPU,
    # outputs
    vis: wp.array[float],
):
    """Only the pass's random draws: two a sample from the receiver's key (their sum is written)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    xy = gb_pixel(gb, i)
    state, base, rot = sampling_begin(ls, i, xy[0], xy[1])
    keep = float(0.0)
    for s in range(ls.count):
        keep += counter_draw(state, s, 0) + counter_draw(state, s, 1)
    vis[i] = keep


@wp.kernel
def covered_receivers(
    offset: int,
    gb: GBufferGPU,
    # outputs
    vis: wp.array[float],
):
    """Only the launch over the receivers: each covered receiver's point read, one value written."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    p = gb.pos[i]
    vis[i] = p[0] + p[1] + p[2]
