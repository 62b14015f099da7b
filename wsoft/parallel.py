"""Device choice and CPU parallelism.

Warp runs one CPU launch on one thread. Every heavy CPU launch in wsoft is therefore
split into chunks that run on a thread pool (a launch releases the GIL while the
compiled kernel runs), so all cores work. On CUDA the same kernel runs as one launch.

Chunked kernels take ``offset: int`` as their first input and index with
``i = wp.tid() + offset``.

Warp compiles (or loads from its cache) a module at its first launch, on whichever thread
launches it. :func:`init_warp` wraps ``Module.load`` once so that every real load is recorded
as an interval; :func:`compile_time` tells how much of a span of time went to it, so the
frame graph reports compilation apart from the passes' times. :func:`on_compile` calls a
function when a module is about to be compiled (its binary is not in the kernel cache), and
:func:`uncached_modules` lists the modules a launch would compile (the command line's
"compiling kernels" line and ``wsoft warmup``).
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import warp as wp

from wsoft.env import threads as env_threads
from wsoft.env import warp_verbose
from wsoft.errors import ParameterError

_POOL: ThreadPoolExecutor | None = None
_INIT = False
_LOAD_LOCK = threading.Lock()
# every real module load (compile or cache load): (start, end) perf_counter seconds and the loading
# thread's CPU seconds; appended under _LOADS_LOCK from any thread
_LOADS: list[tuple[float, float, float]] = []
_LOADS_LOCK = threading.Lock()
_COMPILE_LISTENERS: list[Callable[[str, str], None]] = []
# The estimate of uncached_seconds, per device kind. CPU: the compiling thread's CPU time with a cold
# kernel cache (its wall time on an idle core; on a busy machine the wall time is longer: 17 s for
# 6.9 s of CPU at a load of 9 on 2 cores), measured with Warp 1.19: a `hard` render compiles 9 modules
# in 6.9 s, the RENDER_MODULES among them (with the rasterizer's specialised kernels) in about 6.4 s;
# `pcss` 10 modules in 7.6 s, `essm` 12 in 16.3 s; wsoft's 40 modules 60 s, 1.5 s a module. CUDA: PTX
# for every module took ~1.5 min an architecture; the render's 9 modules at 1.5 s each
COMPILE_SECONDS = {"cpu": {"render": 6.4, "module": 1.5}, "cuda": {"render": 13.5, "module": 1.5}}
RENDER_MODULES = ("wsoft.raster.gbuffer", "wsoft.lightspace.fit", "wsoft.raster.rasterizer", "wsoft.raster.depth_map",
                  "wsoft.raster.horizon", "wsoft.raster.shade")
"""The Warp modules every render compiles (with the rasterizer's specialised kernels, made at its first use)."""

# Warp's per-module compile messages are noise for users; WSOFT_WARP_VERBOSE=1 shows them.
if not warp_verbose():
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
    if warp_verbose():
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
    _time_module_loads()
    _INIT = True


def _time_module_loads() -> None:
    """Wrap Warp's ``Module.load`` (once) to record the calls that compiled or loaded a module.

    ``Module.load`` runs before every launch; it is a load only when it returns an executable the
    module did not hold before (the others are its fast path and are not recorded)."""
    from warp._src.context import Module

    load = Module.load
    if getattr(load, "_wsoft_timed", False):
        return

    def timed_load(self, *args, **kwargs):
        held = tuple(self.execs.values())
        t0, c0 = time.perf_counter(), time.thread_time()
        out = None
        try:
            out = load(self, *args, **kwargs)
            return out
        finally:
            if out is None or out not in held:  # a compile, a cache load, or a failed build
                t1, c1 = time.perf_counter(), time.thread_time()
                with _LOADS_LOCK:
                    _LOADS.append((t0, t1, c1 - c0))

    timed_load._wsoft_timed = True
    timed_load.__wrapped__ = load
    timed_load.__doc__ = load.__doc__
    Module.load = timed_load

    compile_ = getattr(Module, "_compile", None)  # the step of Module.load that builds the binary unless the cache holds it
    if compile_ is None:  # another Warp: no compile notices, timings as above
        return

    def noted_compile(self, device=None, output_dir=None, output_name=None, *args, **kwargs):
        if _COMPILE_LISTENERS and output_dir is not None and output_name is not None and (
                not wp.config.cache_kernels or not os.path.exists(os.path.join(output_dir, output_name))):
            for listener in list(_COMPILE_LISTENERS):
                listener(self.name, str(device) if device is not None else "cpu")
        return compile_(self, device, output_dir, output_name, *args, **kwargs)

    noted_compile.__wrapped__ = compile_
    Module._compile = noted_compile


def on_compile(listener: Callable[[str, str], None]) -> Callable[[], None]:
    """Call ``listener(module_name, device)`` (on the compiling thread) whenever Warp is about to
    compile a module because the kernel cache has no binary of it for that device; returns the
    function that removes the listener."""
    _COMPILE_LISTENERS.append(listener)
    return lambda: _COMPILE_LISTENERS.remove(listener) if listener in _COMPILE_LISTENERS else None


def uncached_modules(device: str, skip: tuple[str, ...] = ()) -> list:
    """The Warp modules defined so far that own kernels, are not loaded on ``device`` and whose
    binary for it is not in the kernel cache: what their first launch would compile. Modules whose
    name starts with one of ``skip`` are left out. Reads Warp's cache layout (the module's
    identifier and output name, as ``Module.load`` looks them up); call it from one thread while no
    module loads."""
    from warp._src.context import _resolve_launch_block_dim, user_modules

    init_warp()
    dev = wp.get_device(device)
    out = []
    for name, module in list(user_modules.items()):
        if not module.kernels or name.startswith(skip):
            continue
        block_dim = _resolve_launch_block_dim(dev, module.options["block_dim"])
        if (dev.context, block_dim) in module.execs:
            continue
        binary = os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(block_dim),
                              module._get_compile_output_name(dev, block_dim=block_dim))  # noqa: SLF001
        if not wp.config.cache_kernels or not os.path.exists(binary):
            out.append(module)
    return out


def referenced_modules(techniques) -> set[str]:
    """The wsoft modules the code of ``techniques`` (names of ``wsoft.techniques``) refers to: each
    technique's own modules and those its functions and classes come from, as imported so far (no
    module is imported here); ``reference`` adds :mod:`wsoft.reference` and :mod:`wsoft.metrics`
    (a comparison's metric passes)."""
    import inspect
    import sys

    out: set[str] = set()
    own = tuple(f"wsoft.techniques.{t}" for t in techniques)
    for name, mod in list(sys.modules.items()):
        if mod is None or not (name in own or name.startswith(tuple(o + "." for o in own))):
            continue
        out.add(name)
        for v in list(vars(mod).values()):
            ref = v.__name__ if inspect.ismodule(v) else getattr(v, "__module__", None)
            if isinstance(ref, str) and ref.startswith("wsoft."):
                out.add(ref)
    if "reference" in techniques:
        out |= {n for n in list(sys.modules) if n == "wsoft.reference" or n.startswith(("wsoft.reference.", "wsoft.metrics"))}
    return out


def uncached_seconds(device: str, skip: tuple[str, ...] = (), techniques=None) -> float:
    """A rough estimate of the seconds a first render compiles for (:data:`COMPILE_SECONDS`): the
    render's own modules (:data:`RENDER_MODULES`) when they are not cached, and a module's average
    for each other uncached wsoft module of :func:`uncached_modules` (those ``techniques`` refer to,
    :func:`referenced_modules`, where it names them). 0 (no estimate) where this Warp's cache layout
    is not the one :func:`uncached_modules` reads."""
    try:
        mods = [m.name for m in uncached_modules(device, skip)]
    except (ImportError, AttributeError, TypeError, KeyError):
        return 0.0
    cost = COMPILE_SECONDS["cpu" if device.startswith("cpu") else "cuda"]
    base = any(m in RENDER_MODULES for m in mods)
    others = [m for m in mods if m.startswith("wsoft.") and m not in RENDER_MODULES]
    if techniques is not None:
        wanted = referenced_modules(techniques)
        others = [m for m in others if m in wanted]
    return base * cost["render"] + len(others) * cost["module"]


def compile_time(t0: float, t1: float) -> tuple[float, float]:
    """Seconds Warp spent compiling or loading modules between ``time.perf_counter()`` readings
    ``t0`` and ``t1``, on any thread: (wall, cpu). Wall is the union of the load intervals inside
    the span (loads on several threads at once count once), cpu the loading threads' CPU time of the
    loads that lie wholly inside it."""
    with _LOADS_LOCK:
        loads = sorted(x for x in _LOADS if x[1] > t0 and x[0] < t1)
    wall = cpu = 0.0
    end = t0
    for a, b, c in loads:
        lo, hi = max(a, end), min(b, t1)
        if hi > lo:
            wall += hi - lo
            end = hi
        if a >= t0 and b <= t1:
            cpu += c
    return wall, cpu


def cpu_threads() -> int:
    """Threads used for CPU launches: ``WSOFT_THREADS`` (:func:`wsoft.env.threads`; a malformed
    value is an error) or the cores this process may use."""
    n = env_threads()
    if n is not None:
        return n
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


_WORKER = threading.local()


def _as_worker(task: Callable[[], None]) -> Callable[[], None]:
    def run():
        _WORKER.active = True
        try:
            task()
        finally:
            _WORKER.active = False

    return run


def run_tasks(tasks: list[Callable[[], None]], device: str) -> None:
    """Run independent launch tasks: on the CPU thread pool, or in order on a GPU stream. Tasks
    that run tasks themselves run those in order (a pool task waiting on tasks queued behind it in
    the same pool would wait forever)."""
    if not tasks:
        return
    if not device.startswith("cpu") or len(tasks) == 1 or cpu_threads() == 1 or getattr(_WORKER, "active", False):
        for t in tasks:
            t()
        return
    for fut in [_pool().submit(_as_worker(t)) for t in tasks]:
        fut.result()


def run_row_blocks(n: int, block: Callable[[int, int], None], min_rows: int = 65536) -> None:
    """``block(start, end)`` over row blocks of ``range(n)``, one block a CPU thread (host NumPy
    work: its loops release the GIL)."""
    run_tasks([lambda a=a, c=c: block(a, a + c) for a, c in chunk_ranges(n, "cpu", min_chunk=min_rows, per_thread=1)], "cpu")


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


def launch_chunked(kernel, n: int, inputs: list, outputs: list, device: str, min_chunk: int = 1024, per_thread: int = 4) -> None:
    """Launch ``kernel`` over ``n`` items, chunked across CPU threads (kernel's first input is
    ``offset``); ``per_thread`` chunks a thread (more: a better balance where items cost unevenly).
    Each thread packs the arguments once (``wp.launch(..., record_cmd=True)``) and replays the
    launch for its other chunks with their offset and size: packing a kernel's structs costs
    20-50 µs a launch, which a short pass of many chunks would otherwise pay for each."""
    ensure_loaded(kernel, device)
    chunks = chunk_ranges(n, device, min_chunk, per_thread)
    if len(chunks) == 1:
        wp.launch(kernel, dim=chunks[0][1], inputs=[chunks[0][0], *inputs], outputs=outputs, device=device)
        return
    recorded: dict[int, wp.Launch] = {}  # thread -> its launch (each thread replays its own)

    def task(start: int, count: int):
        def run():
            cmd = recorded.get(threading.get_ident())
            if cmd is None:
                cmd = wp.launch(kernel, dim=count, inputs=[start, *inputs], outputs=outputs, device=device, record_cmd=True)
                recorded[threading.get_ident()] = cmd
            else:
                cmd.set_dim(count)
                cmd.set_param_at_index(0, start)
            cmd.launch()

        return run

    run_tasks([task(s, c) for s, c in chunks], device)


init_warp()
