"""A new user's first hour: bundled stages by name in the command line and the Python API (and
the closest names on a typo), ``wsoft scenes`` and its catalog, ``--version``, ``render --out`` by
extension and its default name, the "compiling kernels" line and ``wsoft warmup``, argument
errors answered without Warp or USD, help for every option, one spelling of the sweep names;
in the slow mode, the README's Python example from a wheel installed in a fresh virtual
environment, run outside the repository."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
from importlib.metadata import version

import numpy as np
import pytest
import warp as wp
from conftest import ROOT
from PIL import Image

import wsoft
from wsoft import usd_scenes
from wsoft.cli import main, parser, run_captured
from wsoft.io import read_exr

TINY = ("--width", "32", "--height", "24", "--device", "cpu")


def _one_error_line(rc: int, err: str, *needles: str) -> str:
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("wsoft: error: "), err
    assert all(n in lines[0] for n in needles), lines[0]
    return lines[0]


# -- bundled stages by name -------------------------------------------------------------------------


def test_the_python_api_takes_a_bundled_name(tmp_path, monkeypatch):
    """From a folder with no stages in it: load_scene, render, compare, plan, render_sequence and
    bake take a bundled stage's name; the scene's path is the installed file."""
    monkeypatch.chdir(tmp_path)
    scene = wsoft.load_scene("multi_light")
    assert scene.path == str(usd_scenes.path("multi_light")) and scene.total_triangles == 902
    assert wsoft.load_scene("multi_light.usda").path == scene.path
    f = wsoft.render("box_plane", "hard", width=16, height=12, device="cpu")
    assert f.stats["scene"]["path"] == str(usd_scenes.path("box_plane")) and f.V.shape == (12, 16)
    fs = wsoft.compare("box_plane", ["hard"], samples=4, width=16, height=12, device="cpu")
    assert "mae" in fs["hard"].stats["error"]
    assert wsoft.plan("box_plane", ["hard"])["triangles"] == 4
    seq = wsoft.render_sequence("ramp_static", "hard", frames="1:2", width=16, height=12, device="cpu")
    assert seq.times == [1.0, 2.0]
    stats: dict = {}
    wsoft.bake("box_plane", "hard", device="cpu", stats=stats)
    assert stats["meshes"]
    assert os.listdir(tmp_path) == []  # nothing was written where it ran


def test_an_unknown_stage_suggests_the_closest_names(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(wsoft.SceneError, match=r"box_plan: no such file, nor a bundled stage of that name \(did you mean box_plane\?\)"):
        wsoft.load_scene("box_plan")
    with pytest.raises(wsoft.SceneError, match="'multi_light' is a bundled stage: give its name alone"):
        wsoft.render("usd_scenes/multi_light.usda", "hard", width=16, height=12, device="cpu")  # the README's old example, away from the checkout
    with pytest.raises(wsoft.SceneError, match="nope/x.usda: file not found$"):
        wsoft.load_scene("nope/x.usda")
    for argv in (["render", "box_plan", "-t", "hard"], ["compare", "box_plan"], ["plan", "box_plan"],
                 ["bake", "box_plan", "-t", "hard", "--out", "v.usda"], ["render", "penumbra_rmp", "-t", "hard", "--frames", "1:2"]):
        rc, _, err = run_captured(argv)
        _one_error_line(rc, err, f"{argv[1]}: no such file, nor a bundled stage", "did you mean", "`wsoft scenes`")
    assert os.listdir(tmp_path) == []


def test_unknown_techniques_and_sweeps_suggest_the_closest_names():
    rc, _, err = run_captured(["render", "box_plane", "-t", "pcs", "--out", "o.exr"])
    _one_error_line(rc, err, "unknown technique 'pcs' (did you mean pcss", "; techniques: csm, dcs, esm")
    rc, _, err = run_captured(["compare", "box_plane", "-t", "hard", "-t", "esm_soft"])
    _one_error_line(rc, err, "unknown technique 'esm_soft' (did you mean msm_soft")
    rc, _, err = run_captured(["bench", "usd_pipelin", "--quick"])
    _one_error_line(rc, err, "unknown sweep 'usd_pipelin' (did you mean usd-pipeline?)")


def test_sweep_names_are_spelled_one_way():
    """Sweep names join words with "-" (essm-table1); usd_pipeline stays an accepted alias, listed once."""
    from wsoft.bench.harness import SWEEP_ALIASES, SWEEPS, sweep_name

    assert all("_" not in name for name in SWEEPS)
    assert sweep_name("usd_pipeline") == sweep_name("usd-pipeline") == "usd-pipeline"
    assert set(SWEEP_ALIASES.values()) <= set(SWEEPS)
    rc, out, _ = run_captured(["bench", "--help"])
    assert rc == 0 and "usd-pipeline" in out and "usd_pipeline" not in out


# -- wsoft scenes, --version --------------------------------------------------------------------


def test_scenes_lists_every_bundled_stage():
    rc, out, _ = run_captured(["scenes"])
    assert rc == 0
    rows = {line.split()[0]: line for line in out.splitlines()[1:] if line and not line.startswith("A name")}
    assert set(rows) == set(usd_scenes.names())
    assert re.search(r"^forest +56,358,008 +distant, rect +10,195 trees", rows["forest"])
    assert re.search(r"^ramp_slide +62 +rect +1-48 +penumbra_ramp", rows["ramp_slide"])
    assert "rect, disk, sphere, distant" in rows["multi_light"] and "4 sphere" in rows["factory"]
    rc, out, _ = run_captured(["scenes", "--json"])
    js = json.loads(out)
    assert js["box_plane"] == {"triangles": 4, "lights": [["Light", "rect"]], "frames": None, "about": usd_scenes.ABOUT["box_plane"]}


def test_the_catalog_and_the_descriptions_match_the_stages():
    """``catalog.json`` holds what the stages hold (run ``python -m wsoft.scene.catalog`` after
    changing a stage); every stage has a one-line description and no description lacks its stage."""
    from wsoft.scene.catalog import measure

    names = usd_scenes.names()
    cat = usd_scenes.catalog()
    assert sorted(cat) == names, "catalog.json is not the bundled stages: run python -m wsoft.scene.catalog"
    assert sorted(usd_scenes.ABOUT) == names, "wsoft.usd_scenes.ABOUT needs one line per bundled stage"
    assert all(len(line) <= 100 and "\n" not in line for line in usd_scenes.ABOUT.values())
    for name in names:
        assert measure(name) == cat[name], f"{name}: catalog.json is stale: run python -m wsoft.scene.catalog"


def test_version_is_the_installed_packages():
    rc, out, _ = run_captured(["--version"])
    assert rc == 0 and out.strip() == f"wsoft {version('wsoft')}"


# -- what render writes -----------------------------------------------------------------------------


def test_out_writes_what_its_extension_says(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_captured(["render", "box_plane", "-t", "hard", *TINY, "--out", "v.exr"])
    assert rc == 0, err
    v = read_exr("v.exr")["V"]
    rc, out, err = run_captured(["render", "box_plane", "-t", "hard", *TINY, "--out", "v.png"])
    assert rc == 0 and "wrote v.png" in out, err
    png = Image.open("v.png")
    assert png.mode == "I;16" and png.size == (32, 24)  # not an EXR under a .png name
    got = np.asarray(png, dtype=np.float64) / 65535.0
    assert 0.0 < v.mean() < 1.0 and np.abs(got - v).max() <= 0.5 / 65535 + 1e-7
    for bad, needle in (("v.tif", ".tif is not a format wsoft writes"), ("v", "no extension")):
        rc, _, err = run_captured(["render", "box_plane", "-t", "hard", *TINY, "--out", bad])
        _one_error_line(rc, err, f"--out {bad}: {needle}", ".exr: every channel", ".png: V as 16-bit")
    rc, _, err = run_captured(["render", "box_plane", "-t", "hard", *TINY, "--png", "shaded.jpg"])
    _one_error_line(rc, err, "--png shaded.jpg")
    assert sorted(os.listdir(tmp_path)) == ["v.exr", "v.png"]


def test_render_without_out_names_its_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_captured(["render", "box_plane", "-t", "hard", *TINY])
    assert rc == 0, err
    assert "wrote box_plane-hard.exr (no --out and no render settings: named after the stage and technique)" in out
    assert read_exr("box_plane-hard.exr")["V"].shape == (24, 32)
    rc, out, err = run_captured(["render", "ramp_static", "-t", "pcf", *TINY, "--frames", "1:2"])
    assert rc == 0, err
    assert sorted(os.listdir(tmp_path)) == ["box_plane-hard.exr", "ramp_static-pcf.0001.exr", "ramp_static-pcf.0002.exr"]


# -- compilation -------------------------------------------------------------------------------------


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _cold_shade_module(tmp_path, monkeypatch) -> None:
    """Everything a ``hard`` render needs loaded, but the shading module, whose binary is not in
    the (fresh) kernel cache: the next render compiles exactly that module."""
    wsoft.render("box_plane", "hard", width=16, height=12, device="cpu")
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "kernels"))
    wp.get_module("wsoft.raster.shade").unload()


def test_a_compiling_run_says_so_once_and_the_bar_names_the_module(tmp_path, monkeypatch):
    from wsoft import cli

    _cold_shade_module(tmp_path, monkeypatch)
    monkeypatch.setattr(cli.PassProgress, "delay_s", 0.0)
    argv = ["render", "box_plane", "-t", "hard", *TINY, "--out", str(tmp_path / "o.exr")]
    err = _Terminal()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(argv) == 0
    text = err.getvalue()
    assert len(re.findall(r"compiling kernels for cpu \(first run only, ~\d+ s on an idle core(; longer now: load [\d.]+ on \d+ cores?)?\)\n", text)) == 1, text
    assert "(compiling wsoft.raster.shade)" in text  # on the progress bar
    rc, _, err2 = run_captured(argv)  # compiled now: nothing said
    assert rc == 0 and "compiling" not in err2


def test_warmup_compiles_and_then_has_nothing_to_compile(tmp_path, monkeypatch):
    _cold_shade_module(tmp_path, monkeypatch)
    rc, out, err = run_captured(["warmup", "--device", "cpu", "-t", "hard"])
    assert rc == 0, err
    assert re.search(r"^  hard: [\d.]+ s, 1 module compiled$", out, re.M) and re.search(r"^cpu: 1 module compiled in [\d.]+ s$", out, re.M), out
    assert any((tmp_path / "kernels").rglob("*shade*")), "nothing was compiled into the kernel cache"
    rc, out, _ = run_captured(["warmup", "--device", "cpu", "-t", "hard"])
    assert rc == 0 and "cpu: 0 modules compiled in" in out
    rc, _, err = run_captured(["warmup", "-t", "hrad"])
    _one_error_line(rc, err, "did you mean hard")


# -- arguments: answered before Warp and USD, every option explained ---------------------------------

_FRESH = """
import sys, time
import wsoft.cli
cases = [["render", "box_plane", "-t", "nope"], ["render", "box_plan", "-t", "hard"], ["compare", "box_plane", "-t", "pcs"],
         ["plan", "zzz"], ["bake", "box_plane", "-t", "nope", "--out", "v.usda"], ["render", "box_plane", "-t", "hard", "--out", "v.tif"],
         ["render", "box_plane", "-t", "hard", "--device", "gpu"], ["bench", "nope"], ["warmup", "-t", "nope"],
         ["warmup", "--device", "gpu"], ["scenes"], ["--version"]]
for argv in cases:
    t0 = time.perf_counter()
    try:
        rc = wsoft.cli.main(argv)
    except SystemExit as exc:
        rc = exc.code
    print("case", rc, f"{time.perf_counter() - t0:.3f}", file=sys.stderr)
print("loaded:", sorted(m for m in ("warp", "pxr") if m in sys.modules), file=sys.stderr)
"""


def test_argument_errors_and_listings_import_neither_warp_nor_usd(tmp_path):
    """In a fresh interpreter (one subprocess): unknown techniques, stages, sweeps and devices and a
    bad --out extension are refused, and ``scenes`` and ``--version`` answer, without importing
    Warp or USD (what takes seconds)."""
    p = subprocess.run([sys.executable, "-c", _FRESH], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    codes = [int(line.split()[1]) for line in p.stderr.splitlines() if line.startswith("case ")]
    assert codes == [2] * 10 + [0, 0], p.stderr
    assert "loaded: []" in p.stderr, p.stderr


def _subparser(name: str) -> argparse.ArgumentParser:
    ap = parser()
    return next(a for a in ap._actions if a.dest == "cmd").choices[name]  # noqa: SLF001


def test_every_option_of_compare_and_plan_has_help():
    for name in ("compare", "plan", "render", "warmup", "scenes"):
        for action in _subparser(name)._actions:  # noqa: SLF001
            assert action.help, f"{name} {action.option_strings or action.dest} has no help"
    plan_help = _subparser("plan").format_help()
    assert "--width" not in plan_help and "--height" not in plan_help  # options plan does not have


# -- the README's example, installed ------------------------------------------------------------------


def _readme_example() -> str:
    with open(os.path.join(ROOT, "README.md")) as f:
        blocks = re.findall(r"```python\n(.*?)```", f.read(), re.S)
    return next(b for b in blocks if "wsoft.load_scene(" in b)


def _build_isolation() -> list[str]:
    """``--no-build-isolation`` when this Python's setuptools builds wheels as pyproject.toml asks
    (>= 68, and >= 70.1 or the ``wheel`` package beside it); else none: pip fetches the build
    backend, as ``pip install .`` does."""
    from importlib.metadata import PackageNotFoundError

    def v(name: str) -> tuple[int, ...]:
        try:
            return tuple(int(x) for x in re.findall(r"\d+", version(name))[:2])
        except PackageNotFoundError:
            return ()

    st = v("setuptools")
    return ["--no-build-isolation"] if st >= (68,) and (st >= (70, 1) or v("wheel")) else []


@pytest.mark.slow
def test_readme_example_runs_from_a_wheel_outside_the_repository(tmp_path):
    """``pip install .`` (a wheel, non-editable) into a fresh venv that sees this machine's
    packages, then the README's Python example, ``wsoft scenes`` and ``wsoft --version`` from an
    empty folder; the wsoft they run is the installed one."""
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", "reports", "out", ".venv"))
    for link in ("wsoft/bench", "wsoft/usd_scenes"):  # a checkout's links to bench/ and usd_scenes/, not part of the source
        if (src / link).is_symlink():
            (src / link).unlink()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}

    def run(*cmd, cwd=tmp_path, timeout=900):
        p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)
        assert p.returncode == 0, f"{cmd}\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}"
        return p

    run(sys.executable, "-m", "pip", "wheel", "--no-deps", *_build_isolation(), "-w", tmp_path / "wheel", src)
    wheel = next((tmp_path / "wheel").glob("wsoft-*.whl"))
    run(sys.executable, "-m", "venv", "--system-site-packages", tmp_path / "venv")
    py = tmp_path / "venv" / "bin" / "python"
    run(py, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--force-reinstall", "--no-index", wheel)
    work = tmp_path / "work"
    work.mkdir()
    p = run(py, "-c", "import wsoft, wsoft.usd_scenes as s; print(wsoft.__file__); print(s.path('multi_light'))", cwd=work)
    assert all(line.startswith(str(tmp_path / "venv")) for line in p.stdout.split()), p.stdout
    (work / "example.py").write_text(_readme_example())
    run(py, "example.py", cwd=work)
    assert (work / "pcss.exr").is_file() and (work / "vis.usda").is_file()
    wsoft_cmd = tmp_path / "venv" / "bin" / "wsoft"
    assert "multi_light" in run(wsoft_cmd, "scenes", cwd=work).stdout
    assert run(wsoft_cmd, "--version", cwd=work).stdout.strip() == f"wsoft {version('wsoft')}"
