"""Device choice and CPU parallelism.

Warp runs one CPU launch on one thread. Every heavy CPU launch in wsoft is therefore
split into chunks that run on a thread pool (a launch releases the GIL while the
compiled kernel runs), so all cores work. On CUDA the same kernel runs as one launch.

Chunked kernels take ``offset: int`` as their first input and index with
``i = wp.tid() + offset``.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import warp as wp

from wsoft.errors import ParameterError

_POOL: ThreadPoolExecutor | None = None
_INIT = False
_LOAD_LOCK = threading.Lock()

# Warp's per-module compile messages are noise for users; WSOFT_WARP_VERBOSE=1 shows them.
if os.environ.get("WSOFT_WARP_VERBOSE", "") != "1":
    wp.config.log_level = 30  # warnings and errors only
# wsoft never differentiates through its kernels: skip adjoint code (halves compile time)
wp.config.enable_backward = False


def init_warp() -> None:
    """Initialise Warp once (honours ``WARP_CACHE_PATH``).

    On a machine without a CUDA driver, Warp's native library prints a warning on every start;
    unless ``WSOFT_WARP_VERBOSE=1``, stderr is muted for the duration of ``wp.init()`` only.
    """
    global _INIT
    if _INIT:
        return
    if os.environ.get("WSOFT_WARP_VERBOSE", "") == "1":
        wp.init()
    else:
        import sys

        sys.stderr.flush()
        saved = os.dup(2)
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 2)
                wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
    _INIT = True


def cpu_threads() -> int:
    """Threads used for CPU launches: ``WSOFT_THREADS`` or the cores this process may use."""
    env = os.environ.get("WSOFT_THREADS")
    if env:
        return max(1, int(env))
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def resolve_device(name: str | None = None) -> str:
    """``None`` -> ``cuda:0`` when available, else ``cpu``. Unknown names are an error."""
    init_warp()
    if name is None or name == "auto":
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    name = str(name)
    if name == "cuda":
        name = "cuda:0"
    if name == "cpu":
        return name
    if name.startswith("cuda:"):
        if not wp.is_cuda_available():
            raise ParameterError(f"device {name!r} requested but no CUDA device is available; use --device cpu")
        try:
            wp.get_device(name)
        except Exception:
            raise ParameterError(f"device {name!r} does not exist") from None
        return name
    raise ParameterError(f"unknown device {name!r}; use cpu or cuda:N")


def _pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None or _POOL._max_workers != cpu_threads():  # noqa: SLF001
        _POOL = ThreadPoolExecutor(max_workers=cpu_threads(), thread_name_prefix="wsoft-cpu")
    return _POOL


def run_tasks(tasks: list[Callable[[], None]], device: str) -> None:
    """Run independent launch tasks: on the CPU thread pool, or in order on a GPU stream."""
    if not tasks:
        return
    if not device.startswith("cpu") or len(tasks) == 1 or cpu_threads() == 1:
        for t in tasks:
            t()
        return
    for fut in [_pool().submit(t) for t in tasks]:
        fut.result()


def chunk_ranges(n: int, device: str, min_chunk: int = 1024, per_thread: int = 4) -> list[tuple[int, int]]:
    """Split ``range(n)`` into (start, count) chunks: one on CUDA, several per CPU thread."""
    if n <= 0:
        return []
    if not device.startswith("cpu"):
        return [(0, n)]
    parts = max(1, min(cpu_threads() * per_thread, (n + min_chunk - 1) // min_chunk))
    step = (n + parts - 1) // parts
    return [(s, min(step, n - s)) for s in range(0, n, step)]


def ensure_loaded(kernel, device: str) -> None:
    """Compile/load a kernel's module once before several threads launch it."""
    with _LOAD_LOCK:
        wp.load_module(kernel.module, device=device)


def launch_chunked(kernel, n: int, inputs: list, outputs: list, device: str, min_chunk: int = 1024) -> None:
    """Launch ``kernel`` over ``n`` items, chunked across CPU threads (kernel's first input is ``offset``)."""
    ensure_loaded(kernel, device)

    def task(start: int, count: int):
        return lambda: wp.launch(kernel, dim=count, inputs=[start, *inputs], outputs=outputs, device=device)

    run_tasks([task(s, c) for s, c in chunk_ranges(n, device, min_chunk)], device)


init_warp()
