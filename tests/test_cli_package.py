"""The command line as a package of one module per command: arguments checked by their types before
anything loads, a closed output pipe, malformed environment settings, every light in ``compare``'s
table and grid, skipped lights named by every command, and the foundation report's honest lines."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, scene_path, wsoft_cli

# -- a reader that goes away --------------------------------------------------------------------


def test_a_closed_stdout_ends_the_command_quietly():
    """``wsoft techniques | head``: the reader closes the pipe; the command ends without a message."""
    p = subprocess.Popen([sys.executable, "-m", "wsoft", "techniques"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=300) in (0, 141) and err == ""


# -- arguments checked before anything loads ----------------------------------------------------


@pytest.mark.parametrize("argv,flag", [
    (["render", "no_such_stage_x", "-t", "hard", "--width", "0"], "--width"),
    (["render", "no_such_stage_x", "-t", "hard", "--height", "-4"], "--height"),
    (["render", "no_such_stage_x", "-t", "hard", "--width", "2.5"], "--width"),
    (["render", "no_such_stage_x", "-t", "hard", "--pixel-samples", "0"], "--pixel-samples"),
    (["render", "no_such_stage_x", "-t", "hard", "--pixel-samples", "65"], "--pixel-samples"),
    (["compare", "no_such_stage_x", "--samples", "0"], "--samples"),
    (["compare", "no_such_stage_x", "--width", "0"], "--width"),
    (["bake", "no_such_stage_x", "-t", "hard", "--out", "x.usda", "--texture-size", "0"], "--texture-size"),
    (["bake", "no_such_stage_x", "-t", "hard", "--out", "x.usda", "--crease-angle", "200"], "--crease-angle"),
    (["bench", "foundation", "--workers", "0"], "--workers"),
])
def test_a_number_out_of_range_names_its_flag_before_the_stage_is_looked_up(argv, flag):
    r = wsoft_cli(*argv)
    assert r.returncode == 2 and r.stderr.startswith(f"wsoft: error: {flag} ") and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "no_such_stage_x" not in r.stderr  # the stage was never looked up


@pytest.mark.parametrize("cmd", ["compare", "render"])
def test_a_set_prefix_naming_a_technique_not_given_says_so(cmd, tmp_path):
    r = wsoft_cli(cmd, "box_plane", "-t", "pcss", "--set", "essm.H=2", "--width", "8", "--height", "6",
                  *(["--out-dir", tmp_path] if cmd == "compare" else ["--out", tmp_path / "o.exr"]))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "--set essm.H=2: essm is not among the -t techniques (pcss)" in r.stderr


def test_a_budget_split_between_lights_says_the_whole_and_each_share():
    from wsoft.cli.common import auto_line

    a = {"choice": {"setting": "pcss(x)", "predicted_ms": 80.0, "predicted_error": 0.01}, "runner_up": None,
         "goal": {"budget_ms": 100.0}, "candidates": [1, 2]}
    assert auto_line("Rect", a, 2).startswith("auto (budget 200 ms over 2 lights, 100 ms each): Rect: pcss(x)")
    assert auto_line("Rect", a).startswith("auto (budget 100 ms): Rect:")


# -- environment settings -----------------------------------------------------------------------


@pytest.mark.parametrize("name,value", [
    ("WSOFT_THREADS", "abc"), ("WSOFT_THREADS", "2.5"), ("WSOFT_THREADS", "0"), ("WSOFT_THREADS", "-3"),
    ("WSOFT_WARP_VERBOSE", "yes"), ("WSOFT_CACHE_DIR", "FILE"), ("WSOFT_SCENES", "MISSING"),
])
def test_a_malformed_environment_setting_is_one_line_and_exit_2(name, value, monkeypatch, tmp_path):
    if value == "FILE":
        value = str(tmp_path / "a_file")
        (tmp_path / "a_file").write_text("")
    elif value == "MISSING":
        value = str(tmp_path / "missing")
    monkeypatch.setenv(name, value)
    r = wsoft_cli("techniques")
    assert r.returncode == 2 and r.stdout == "", r.stderr
    assert r.stderr.startswith(f"wsoft: error: environment setting {name}=") and len(r.stderr.strip().splitlines()) == 1


def test_wsoft_threads_is_read_strictly(monkeypatch):
    from wsoft.errors import ParameterError
    from wsoft.parallel import cpu_threads

    monkeypatch.setenv("WSOFT_THREADS", "3")
    assert cpu_threads() == 3
    monkeypatch.setenv("WSOFT_THREADS", "0")
    with pytest.raises(ParameterError, match="WSOFT_THREADS='0'"):
        cpu_threads()


# -- every light in compare, and the lights skipped ----------------------------------------------


def test_compare_shows_every_light_and_names_the_skipped_dome_once(tmp_path):
    from PIL import Image

    from wsoft.metrics.figures import grid_size

    out = tmp_path / "cmp"
    r = wsoft_cli("compare", "multi_light", "-t", "hard", "--samples", "4", "--width", "32", "--height", "24", "--device", "cpu",
                  "--out-dir", out)
    assert r.returncode == 0, r.stderr
    lights = ["Rect", "Disk", "Sphere", "Sun"]
    md = (out / "multi_light-compare.md").read_text()
    short = md[md.index("| technique | light | frame ms |"):].splitlines()
    assert [row.split("|")[1:3] for row in short[2:7]] == [[" reference ", " - "]] + [[" hard ", f" {l} "] for l in lights]
    size = Image.open(out / "multi_light-compare.png").size  # a shaded, a ꟻLIP and a V row per light
    assert all(abs(a - b) <= 1 for a, b in zip(size, [s * 110 for s in grid_size(2, 32, 24, tiles=2 + len(lights))[:2]]))
    dome = [line for line in r.stderr.splitlines() if "/World/Lights/Dome" in line]
    assert len(dome) == 1 and dome[0].startswith("warning: ") and "skipped" in dome[0] and "not the sky" in dome[0]


def _dome_beside(tmp_path, stage: str, start: int, end: int) -> str:
    """A stage that sublayers the bundled ``stage`` and adds a DomeLight."""
    path = tmp_path / f"{stage}_dome.usda"
    path.write_text(f'#usda 1.0\n(\n    subLayers = [@{scene_path(stage + ".usda")}@]\n    startTimeCode = {start}\n'
                    f'    endTimeCode = {end}\n)\n\ndef DomeLight "ExtraDome"\n{{\n}}\n')
    return str(path)


@pytest.mark.parametrize("argv", [
    ["render", "-t", "hard", "--out", "{tmp}/r.exr"],
    ["render", "-t", "hard", "--frames", "1:2", "--out", "{tmp}/r.exr"],
    ["compare", "-t", "hard", "--samples", "4", "--frames", "1:2", "--out-dir", "{tmp}/c"],
    ["bake", "-t", "hard", "--out", "{tmp}/b.usda"],
])
def test_every_command_names_a_skipped_light_once(argv, tmp_path):
    stage = _dome_beside(tmp_path, "ramp_static", 1, 24)
    r = wsoft_cli(argv[0], stage, *[a.replace("{tmp}", str(tmp_path)) for a in argv[1:]],
                  *(["--width", "24", "--height", "16"] if argv[0] != "bake" else []), "--device", "cpu")
    assert r.returncode == 0, r.stderr
    dome = [line for line in r.stderr.splitlines() if "/ExtraDome" in line]
    assert len(dome) == 1 and dome[0].startswith("warning: ") and "skipped" in dome[0] and "not the sky" in dome[0], r.stderr


# -- the README's Python example ----------------------------------------------------------------


def test_the_readme_examples_counters_are_not_empty():
    import re

    with open(os.path.join(ROOT, "README.md")) as f:
        block = next(b for b in re.findall(r"```python\n(.*?)```", f.read(), re.S) if "wsoft.load_scene(" in b)
    head = block[: block.index("frame.write_exr")]
    assert "frame.counters(" in head
    ns: dict = {}
    exec(head.replace("width=640, height=480", "width=32, height=24"), ns)  # noqa: S102  (the README's own lines)
    assert ns["frame"].counters("Disk")


# -- the foundation report ----------------------------------------------------------------------


def _render_row(ms: float) -> dict:
    return {"scene": "box_plane", "width": 160, "device": "cpu", "timings_ms": {"light_depth[L]": ms},
            "pass_kinds": {"light_depth[L]": "light_map"}, "cpu_ms": {"light_depth[L]": ms * 1.9}}


def test_the_cpu_use_target_is_not_claimed_when_no_pass_reached_50_ms():
    import wsoft.bench.foundation as fnd

    text = "\n".join(fnd.cpu_use_section([_render_row(30.0)]))
    assert "not measured at this size" in text and "met." not in text
    assert "met." in "\n".join(fnd.cpu_use_section([_render_row(80.0)]))


def test_a_throughput_row_without_embree_or_one_thread_figures_shows_dashes():
    from wsoft.bench.foundation_rays import rays_sections

    r = {"case": {"kind": "ray_throughput"}, "scene": "contact", "light": "/World/Light", "samples": 4, "threads": None, "rays": 100,
         "packets_identical": True, "embree": None}
    for kind in ("rays", "pass"):
        for m in ("ray", "packet"):
            r[f"{kind}_{m}_mrays_s"], r[f"{kind}_{m}_cpu_over_wall"] = 5.0, 1.0
    text = "\n".join(rays_sections([r]))
    assert "| contact |" in text and "None" not in text and "nan" not in text


def test_the_install_command_follows_how_wsoft_is_installed(monkeypatch):
    import importlib.metadata as md

    from wsoft.bench.common import install_command

    class Dist:
        def __init__(self, text):
            self.text = text

        def read_text(self, name):
            return self.text

    monkeypatch.setattr(md, "distribution", lambda name: Dist('{"url": "file:///x.whl", "archive_info": {}}'))
    assert install_command("peers") == "pip install 'wsoft[peers]'"
    monkeypatch.setattr(md, "distribution", lambda name: Dist('{"url": "file:///src", "dir_info": {"editable": true}}'))
    assert install_command("peers").startswith("pip install -e '.[peers]'")


def test_narrow_log_axes_get_tick_labels():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.bench.common import log_ticks

    fig, ax = plt.subplots()
    ax.plot([31.0, 36.5], [0.0026, 0.0058])
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_ticks(ax)
    fig.canvas.draw()
    for axis in (ax.xaxis, ax.yaxis):
        labels = [t.get_text() for t in axis.get_ticklabels() if t.get_text()]
        assert len(labels) >= 2, labels
    plt.close(fig)
    assert np.isfinite(ax.get_xlim()).all()


# -- the compile estimate -----------------------------------------------------------------------


def test_the_compile_estimate_counts_the_render_and_the_modules_the_techniques_use(monkeypatch):
    import types

    import wsoft.techniques.essm  # noqa: F401  (its module and what it refers to, imported)
    from wsoft import parallel

    names = ["wsoft.raster.gbuffer", "wsoft.raster.shade", "wsoft.techniques.essm", "wsoft.techniques.vsm", "warp.utils",
             *sorted(m for m in parallel.referenced_modules(["essm"]) if m.startswith("wsoft.accel"))]
    monkeypatch.setattr(parallel, "uncached_modules", lambda device, skip=(): [types.SimpleNamespace(name=n) for n in names])
    cost = parallel.COMPILE_SECONDS["cpu"]
    own = 1 + sum(n.startswith("wsoft.accel") for n in names)
    assert parallel.uncached_seconds("cpu", (), ["essm"]) == cost["render"] + own * cost["module"]
    assert parallel.uncached_seconds("cpu") == cost["render"] + (own + 1) * cost["module"]  # vsm too; never warp's own
    assert "wsoft.techniques.essm" in parallel.referenced_modules(["essm"])


def test_the_compile_notice_says_when_the_machine_is_busy(monkeypatch):
    from wsoft.cli import progress

    monkeypatch.setattr(os, "getloadavg", lambda: (11.3, 9.0, 6.0))
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    assert progress.busy() == "; longer now: load 11.3 on 2 cores"
    monkeypatch.setattr(os, "getloadavg", lambda: (1.0, 1.0, 1.0))
    assert progress.busy() == ""
