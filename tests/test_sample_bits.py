"""The light samples' cheap paths give the same bits as the plain formulas: the stratum of a
power-of-two grid by mask and shift with a multiplication by 1/m, and the pair of counter-based
draws that shares its first hash (the reference's frames depend on both, bit for bit)."""

from __future__ import annotations

import numpy as np
import warp as wp

import wsoft.parallel  # noqa: F401
from wsoft.lightspace.samples import counter_draw, counter_pair, stratified_sample


@wp.kernel
def both_strata(
    m: int,
    jitter: wp.array[wp.vec2],
    # outputs
    fast: wp.array[wp.vec2],
    plain: wp.array[wp.vec2],
):
    i = wp.tid()
    s = i % (m * m)
    j = jitter[i]
    fast[i] = stratified_sample(s, m * m, m, j, wp.vec2(0.0, 0.0))
    plain[i] = wp.vec2((float(s % m) + j[0]) / float(m), (float(s // m) + j[1]) / float(m))


@wp.kernel
def both_draws(
    key: wp.uint32,
    # outputs
    pair: wp.array[wp.vec2],
    single: wp.array[wp.vec2],
):
    s = wp.tid()
    pair[s] = counter_pair(key, s, 2)
    single[s] = wp.vec2(counter_draw(key, s, 2), counter_draw(key, s, 3))


def test_power_of_two_strata_match_the_division_bit_for_bit(device):
    rng = np.random.default_rng(7)
    for m in (2, 4, 8, 16, 32, 3, 5):  # 3 and 5: the division path itself
        n = 4096
        j = rng.random((n, 2), dtype=np.float32)
        j[:8] = [[0.0, 0.0], [0.99999994, 0.99999994], [0.5, 0.5], [0.25, 0.75], [1e-30, 1e-7], [0.1, 0.9], [0.3333333, 0.6666667], [0.0, 0.99999994]]
        jit = wp.array(j, dtype=wp.vec2, device=device)
        fast = wp.empty(n, dtype=wp.vec2, device=device)
        plain = wp.empty(n, dtype=wp.vec2, device=device)
        wp.launch(both_strata, n, inputs=[m, jit], outputs=[fast, plain], device=device)
        f, p = fast.numpy(), plain.numpy()
        assert np.array_equal(f.view(np.uint32), p.view(np.uint32)), m
        assert f.min() >= 0.0 and f.max() <= 1.0  # a draw of 1 - 2^-24 in the last stratum rounds to 1.0 on both paths


def test_a_pair_of_draws_is_the_two_single_draws(device):
    n = 2048
    pair = wp.empty(n, dtype=wp.vec2, device=device)
    single = wp.empty(n, dtype=wp.vec2, device=device)
    wp.launch(both_draws, n, inputs=[wp.uint32(0x9E3779B9)], outputs=[pair, single], device=device)
    a, b = pair.numpy(), single.numpy()
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert len(np.unique(a[:, 0])) > n - 5  # the draws differ from sample to sample
