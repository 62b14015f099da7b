"""The regression gate's host workload: a fixed CPU kernel that none of wsoft's code takes part in,
timed before each timed round (:mod:`wsoft.bench.regress_rounds`) to measure how fast the host ran
at that moment. It runs as the frames run, one launch per thread on as many threads as wsoft's CPU
launches use (:func:`wsoft.parallel.cpu_threads`), each from its own Python thread of a pool of its
own, so that what the host does to threaded launches (cores taken by other processes, threads
waiting for one) falls on it as on the frames. Its own module, so that comparing rows
(``wsoft regress``) does not import Warp."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import warp as wp


@wp.kernel
def host_work(seed: wp.uint32, steps: int, first: int,
              # outputs
              out: wp.array(dtype=float)):
    """``steps`` draws of an LCG per thread (``first`` + its index), a square root and a sine each."""
    i = first + wp.tid()
    h = wp.uint32(i) * wp.uint32(747796405) + seed
    acc = float(0.0)
    for _ in range(steps):
        h = h * wp.uint32(1664525) + wp.uint32(1013904223)
        x = float(h >> wp.uint32(8)) * (1.0 / 16777216.0)
        acc = acc + wp.sqrt(x) * wp.sin(acc + x)
    out[i] = acc


_POOL: ThreadPoolExecutor | None = None


def host_once(steps: int, threads: int) -> tuple[float, float]:
    """The workload once, ``threads`` Warp threads of ``steps`` draws on the CPU device, split into
    one launch per CPU launch thread: (wall-clock ms, CPU ms of this process)."""
    global _POOL
    from wsoft.parallel import cpu_threads

    n = max(1, min(cpu_threads(), threads))
    if _POOL is None or _POOL._max_workers != n:  # noqa: SLF001
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="wsoft-host")
    out = wp.empty(threads, dtype=float, device="cpu")
    cuts = [threads * k // n for k in range(n + 1)]

    def part(k: int) -> None:
        wp.launch(host_work, dim=cuts[k + 1] - cuts[k], inputs=[wp.uint32(7), steps, cuts[k]], outputs=[out], device="cpu")

    c0, w0 = time.process_time(), time.perf_counter()
    list(_POOL.map(part, range(n)))
    wp.synchronize_device("cpu")
    return (time.perf_counter() - w0) * 1e3, (time.process_time() - c0) * 1e3
