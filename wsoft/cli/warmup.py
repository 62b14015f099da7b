"""``wsoft warmup``: every kernel compiled once into Warp's kernel cache, so later runs start at once."""

from __future__ import annotations

import time

import wsoft.cli.args as a
from wsoft.cli.common import check_device


def add_parser(sub, one_of: str) -> None:
    w = sub.add_parser("warmup", help="compile every technique's kernels once (Warp's kernel cache), so later runs start at once",
                       formatter_class=a.Help)
    a.device(w, "a device to compile for (repeatable; default: cpu and the default device, cuda:0 when available)", repeat=True)
    w.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE",
                   help="compile this technique's kernels only (repeatable; default: every technique, the metric passes and "
                   "every other kernel module); " + one_of)
    w.set_defaults(fn=run)


def _modules(n: int) -> str:
    return f"{n} module{'' if n == 1 else 's'} compiled"


def run(args) -> int:
    """Compile into Warp's kernel cache, once per device, the kernels of every technique (a tiny
    render of each on ``box_plane``, default parameters), of the metric passes (a comparison) and
    every other kernel module wsoft defines; with ``--technique``, those techniques' only. Prints
    each technique's time and the total."""
    devices = args.device or ["cpu", None]
    for d in devices:
        check_device(d)
    from wsoft.techniques import check_names

    check_names(args.technique or [])
    import warp as wp

    import wsoft
    from wsoft.errors import WsoftError
    from wsoft.parallel import on_compile, resolve_device, uncached_modules
    from wsoft.techniques import TECHNIQUES

    scene = wsoft.load_scene("box_plane")
    compiled: list[str] = []
    remove = on_compile(lambda module, device: compiled.append(module))
    try:
        for dev in dict.fromkeys(resolve_device(d) for d in devices):
            t0, n0 = time.perf_counter(), len(compiled)
            print(f"{dev} (kernel cache {wp.config.kernel_cache_dir}):", flush=True)
            for name in args.technique or TECHNIQUES:
                t, n = time.perf_counter(), len(compiled)
                try:
                    wsoft.render(scene, name, width=16, height=12, device=dev)
                except WsoftError as exc:
                    print(f"  {name}: not compiled ({exc.line()})")
                    continue
                print(f"  {name}: {time.perf_counter() - t:.1f} s, {_modules(len(compiled) - n)}", flush=True)
            if not args.technique:
                t, n = time.perf_counter(), len(compiled)
                wsoft.compare(scene, ["hard"], samples=4, width=16, height=12, device=dev)
                for module in uncached_modules(dev):
                    wp.load_module(module, device=dev)
                print(f"  metric passes and the other modules: {time.perf_counter() - t:.1f} s, {_modules(len(compiled) - n)}")
            print(f"{dev}: {_modules(len(compiled) - n0)} in {time.perf_counter() - t0:.1f} s")
    finally:
        remove()
    return 0
