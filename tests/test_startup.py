"""Honest and quick start-up: kernel compilation is timed apart from the passes, the command line
parses its arguments without importing Warp or USD, and progress bars appear only on a terminal."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp
from conftest import ROOT, scene_path

import wsoft
from wsoft.graph import FrameGraph, Key, Pass


def python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=ROOT, timeout=300)


# -- compilation is not a pass's time -------------------------------------------------------------


@wp.kernel(module="unique")
def fill_ones(n: int,
              # outputs
              out: wp.array[float]):
    i = wp.tid()
    if i < n:
        out[i] = 1.0


def test_a_cold_compile_is_reported_apart_from_the_pass(device, tmp_path, monkeypatch):
    """A module compiled on a worker thread during a pass (a fresh kernel cache): its time is the
    pass's ``compile_ms``, not its ``ms``; the second run compiles nothing."""
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    fill_ones.module.unload()
    out_key = Key("ones")

    def run(res):
        out = wp.zeros(16, dtype=float, device=device)
        with ThreadPoolExecutor(1) as pool:  # the first launch, so the load, on another thread
            pool.submit(lambda: wp.launch(fill_ones, dim=16, inputs=[16], outputs=[out], device=device)).result()
        return {out_key: out}

    graph = FrameGraph()
    graph.add(Pass("ones", (), (out_key,), run))
    res, (first,) = graph.execute([out_key], device)
    assert np.all(res[out_key].numpy() == 1.0)
    assert any(tmp_path.rglob("*")), "the kernel was not compiled into the fresh cache"
    assert first["compile_ms"] > 0.0
    assert first["ms"] < first["compile_ms"]  # compiling even one kernel costs far more than running it
    _, (second,) = graph.execute([out_key], device)
    assert second["compile_ms"] == 0.0


def test_a_render_reports_compilation_outside_its_total(device, tmp_path, monkeypatch):
    """A render whose shading module compiles afresh: ``timings_ms["compile"]`` holds it, ``total`` and the
    ``shade`` pass do not."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    wsoft.render(scene, "hard", width=16, height=12, device=device)  # everything else loaded
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    wp.get_module("wsoft.raster.shade").unload()
    t0 = time.perf_counter()
    f = wsoft.render(scene, "hard", width=16, height=12, device=device)
    wall_ms = 1e3 * (time.perf_counter() - t0)
    st = f.stats
    assert st["timings_ms"]["compile"] > 0.0
    assert st["timings_ms"]["shade"] < st["timings_ms"]["compile"]
    assert st["timings_ms"]["total"] + st["timings_ms"]["compile"] <= wall_ms + 1.0
    assert "compile" not in st["cpu_ms"] and set(st["timings_ms"]) == set(st["passes"]) | {"total", "compile"}
    again = wsoft.render(scene, "hard", width=16, height=12, device=device)
    assert again.stats["timings_ms"]["compile"] == 0.0


# -- the command line starts without Warp or USD ---------------------------------------------------

_NO_WARP = """
import sys
import wsoft.cli
for argv in (["--help"], ["render", "--help"], ["render"], ["render", "x.usda", "-t", "hard", "--width", "abc", "--out", "o.exr"], ["nope"]):
    try:
        wsoft.cli.main(argv)
    except SystemExit as exc:
        print("exit", exc.code)
print("loaded:", sorted(m for m in ("warp", "pxr") if m in sys.modules))
"""


def test_parsing_arguments_imports_neither_warp_nor_usd():
    p = python(_NO_WARP)
    assert p.returncode == 0, p.stderr
    assert p.stdout.count("exit 0") == 2 and p.stdout.count("exit 2") == 3
    assert "loaded: []" in p.stdout


def test_help_exits_zero_with_the_usage():
    p = subprocess.run([sys.executable, "-m", "wsoft", "--help"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0 and p.stdout.startswith("usage: wsoft") and "render" in p.stdout and "techniques" in p.stdout


def test_public_api_after_importing_submodules_first():
    """``wsoft.render`` and ``wsoft.bake`` are the functions whatever was imported first; a module
    imported on its own sees Warp configured (no adjoint code: each package that defines Warp code
    imports wsoft.parallel first); the registry's names agree with the technique classes."""
    p = python("import wsoft.lightspace.bitmask, wsoft.raster.shade, wsoft.scene.device, wsoft.techniques.hard, wsoft.metrics\n"
               "import wsoft.pipeline, wsoft.baking, wsoft\n"
               "import warp as wp\n"
               "for m in ('wsoft.lightspace.bitmask', 'wsoft.raster.shade', 'wsoft.scene.device', 'wsoft.techniques.hard'):\n"
               "    assert wp.get_module(m).options['enable_backward'] is False, m\n"
               "assert callable(wsoft.bake) and wsoft.bake.__name__ == 'bake', wsoft.bake\n"
               "from wsoft.techniques import NAMES, TECHNIQUES\n"
               "assert callable(wsoft.render) and wsoft.render.__name__ == 'render', wsoft.render\n"
               "assert callable(wsoft.compare) and callable(wsoft.plan) and callable(wsoft.load_scene)\n"
               "assert tuple(wsoft.TECHNIQUES) == NAMES and TECHNIQUES is wsoft.TECHNIQUES\n"
               "assert issubclass(wsoft.SceneError, wsoft.WsoftError) and wsoft.Frame and wsoft.FrameSet and wsoft.Scene\n"
               "assert '| parameter |' in TECHNIQUES['pcss'].__doc__\n"
               "print('ok')")
    assert p.returncode == 0 and "ok" in p.stdout, p.stderr
    p = python("import wsoft\nprint(wsoft.techniques.get_technique('pcss').name, hasattr(wsoft, 'no_such_thing'))")
    assert p.returncode == 0 and p.stdout.split() == ["pcss", "False"], p.stderr


# -- progress only on a terminal -------------------------------------------------------------------

_RENDER = ["render", scene_path("box_plane.usda"), "-t", "hard", "--width", "16", "--height", "12", "--device", "cpu"]


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_on_a_terminal(tmp_path, monkeypatch):
    from wsoft import cli

    monkeypatch.setattr(cli.PassProgress, "delay_s", 0.0)  # show it at once: the render is short
    err = _Terminal()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        rc = cli.main([*_RENDER, "--out", str(tmp_path / "t.exr")])
    assert rc == 0 and "pass" in err.getvalue() and "hard" in err.getvalue()


def test_no_progress_bar_when_piped(tmp_path):
    p = python("import sys\nfrom wsoft import cli\ncli.PassProgress.delay_s = 0.0\nsys.exit(cli.main(sys.argv[1:]))",
               *_RENDER, "--out", str(tmp_path / "p.exr"))
    assert p.returncode == 0, p.stderr
    assert "\r" not in p.stderr + p.stdout and "passes [" not in p.stderr + p.stdout
