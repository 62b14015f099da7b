"""Techniques from other packages (entry-point group ``wsoft.techniques``): the README's example
plugin, installed as a distribution on a temporary path (its module and a ``.dist-info`` with the
entry point, as ``pip install`` lays them out), is registered, passes the contract tests, renders
through ``render``, ``compare``, ``plan`` and the command line, and joins the sweeps that take
every technique; broken plugins are one warning line each, naming the entry point, and the rest
keeps working."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings

import pytest
import test_contract as contract
from conftest import ROOT, scene_path, wsoft_cli

import wsoft
from wsoft.techniques import TECHNIQUES, PluginWarning, bundled_names, names, reload_plugins

README = os.path.join(ROOT, "README.md")


def readme_block(name: str) -> str:
    """The fenced block after ``<!-- plugin-example: NAME -->`` in the README."""
    text = open(README).read()
    m = re.search(r"<!-- plugin-example: " + re.escape(name) + r" -->\n```\w*\n(.*?)```", text, re.S)
    assert m, f"no plugin example {name} in the README"
    return m.group(1)


def install(site, dist: str, module: str | None, source: str | None, entry_points: dict[str, str]) -> None:
    """A distribution ``dist`` on ``site``: ``module.py`` with ``source``, and its metadata with
    ``entry_points`` in the group ``wsoft.techniques``."""
    if module:
        (site / f"{module}.py").write_text(source)
    info = site / f"{dist.replace('-', '_')}-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text("[wsoft.techniques]\n" + "".join(f"{k} = {v}\n" for k, v in entry_points.items()))


@pytest.fixture
def site(tmp_path, monkeypatch):
    """A folder on ``sys.path`` holding the README's plugin, installed; the registry forgets it after."""
    site = tmp_path / "site"
    site.mkdir()
    source = readme_block("tent_pcf.py")
    project = readme_block("pyproject.toml")
    entry = re.search(r'\[project\.entry-points\."wsoft\.techniques"\]\n(\w+) = "([\w.:]+)"', project)
    install(site, "wsoft-tent-pcf", "tent_pcf", source, {entry.group(1): entry.group(2)})
    monkeypatch.syspath_prepend(str(site))
    reload_plugins()
    yield site
    monkeypatch.undo()
    sys.modules.pop("tent_pcf", None)
    reload_plugins()


def test_the_plugin_keeps_the_technique_contract(site):
    assert "tent_pcf" in TECHNIQUES and "tent_pcf" in names() and "tent_pcf" not in bundled_names()
    cls = TECHNIQUES["tent_pcf"]
    assert cls.__module__ == "tent_pcf" and cls.declaration_problem() is None
    for check in (contract.check_manual, contract.check_bad_values, contract.check_settings, contract.check_passes,
                  contract.check_tolerance, contract.check_immutable):
        check("tent_pcf")
    assert "| `radius` |" in cls.__doc__  # its manual got its parameter table
    assert "tent_pcf" not in wsoft.techniques.markdown_table()  # the README's table lists the bundled techniques


def test_the_plugin_renders_compares_and_is_planned(site):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "tent_pcf", width=48, height=36, device="cpu", radius=1)
    assert f.stats["technique"] == "tent_pcf" and f.stats["pass_stages"]["tent_pcf[Light]"] == "shadow"
    assert 0.5 < f.V.mean() < 1.0 and (f.V < 0.5).any()
    fs = wsoft.compare(scene, ["tent_pcf", "pcf"], width=48, height=36, device="cpu", samples=16)
    assert fs["tent_pcf"].stats["error"]["mae"] < 0.05 and set(fs.stats["shared_passes"]) >= {"light_depth[Light]@1024"}
    p = wsoft.plan(scene)
    assert {"light_depth[Light]@1024", "tent_pcf[Light]", "horizon_tent_pcf[Light]"} <= set(p["techniques"]["tent_pcf"])


def test_the_command_line_lists_and_renders_the_plugin(site, tmp_path):
    p = wsoft_cli("techniques")
    text = p.stdout
    assert p.returncode == 0 and "tent_pcf: percentage-closer filtering with tent-weighted taps" in text and "  pass shadow: gbuffer, light_depth -> visibility" in text
    exr = tmp_path / "t.exr"
    p = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "tent_pcf", "--set", "radius=3", "--width", "32", "--height", "24",
                  "--device", "cpu", "--out", exr)
    assert p.returncode == 0 and exr.stat().st_size > 0, p.stderr


def test_the_sweeps_over_every_technique_take_the_plugin(site, tmp_path):
    """``bench pareto`` sets the plugin up at each quality setting and map size; ``bench adversarial``
    renders it through the command line on its cases."""
    from wsoft.bench import adversarial, pareto

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    mine = [(t, p) for t, p in pareto.settings(scene, scene.lights[0], [1024, 2048], quick=False) if t == "tent_pcf"]
    assert mine == [("tent_pcf", {"shadow_map_size": s, **q}) for s in (1024, 2048) for q in TECHNIQUES["tent_pcf"].quality_settings()]
    assert adversarial.technique_args("tent_pcf") == ["--set", "shadow_map_size=256"]
    cases = [c for c in adversarial.CASES if c.name in ("huge_far_triangle", "cutout_8bit", "broken_syntax")]
    ran = {case.name: problems for case, technique, res, problems in adversarial.run_all(str(tmp_path), ["tent_pcf"], cases)}
    assert ran == {"huge_far_triangle": [], "cutout_8bit": [], "broken_syntax": []}


def test_broken_plugins_are_one_line_warnings_and_the_rest_works(site):
    """An entry point that cannot be imported, one that is not a Technique, one named otherwise than
    its class, and one taking a bundled technique's name: each left out with one warning line
    naming it; the good plugin and the bundled techniques stay."""
    install(site, "wsoft-broken", None, None, {"no_module": "no_such_module:Nope", "not_a_technique": "tent_pcf:TentPCFParams",
                                               "misnamed": "tent_pcf:TentPCF", "hard": "tent_pcf:TentPCF"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        techniques = reload_plugins()
    lines = {str(w.message) for w in caught if issubclass(w.category, PluginWarning)}
    assert len(lines) == 4 and all("\n" not in w for w in lines)
    expect = {"no_module = no_such_module:Nope": "cannot be imported: ModuleNotFoundError",
              "not_a_technique = tent_pcf:TentPCFParams": "is not a subclass of wsoft.techniques.Technique",
              "misnamed = tent_pcf:TentPCF": "its class is named 'tent_pcf', not 'misnamed'",
              "hard = tent_pcf:TentPCF": "'hard' is already a bundled technique"}
    for where, why in expect.items():
        assert any(f"technique plugin {where} (entry point group wsoft.techniques): left out" in w and why in w for w in lines), (where, lines)
    assert "tent_pcf" in techniques and techniques["hard"].__module__ == "wsoft.techniques.hard"
    assert not {"no_module", "not_a_technique", "misnamed"} & set(techniques)


def test_a_fresh_process_finds_the_installed_plugin(site):
    """Entry points are read from the installed metadata at start-up: ``wsoft techniques`` in a new
    interpreter lists the plugin (the names without importing it, for ``--help``, too)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.run([sys.executable, "-m", "wsoft", "techniques"], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0 and "tent_pcf: percentage-closer filtering" in p.stdout, p.stderr
    p = subprocess.run([sys.executable, "-m", "wsoft", "render", "--help"], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0 and "tent_pcf" in p.stdout


def test_the_plugin_draws_a_cube_map_around_a_light_that_surrounds_its_receivers(site, tmp_path):
    """The README's plugin has LightViewParams' ``cube``: a sphere light inside a closed lamp shade
    gets a cube map, every receiver in shadow, no warning about receivers left unshadowed."""
    from wsoft.stages.adversarial import b_lamp_sphere

    scene = wsoft.load_scene(b_lamp_sphere(str(tmp_path)))
    f = wsoft.render(scene, "tent_pcf", width=48, height=36, device="cpu", shadow_map_size=512)
    assert len(f.stats["counters"]["techniques"]["tent_pcf"]["Light"]["cube_faces"]) == 6
    assert not [w for w in f.stats.get("warnings", []) if "unshadowed" in w]
    assert f.V[f["A"] > 0].max() <= 0.03


def test_a_plugin_that_draws_light_maps_without_cube_is_told_so_when_it_registers(site):
    """Params that do not subclass LightViewParams (no ``cube``) and no ``cube_refusal``: the plugin
    is kept, with one warning line naming it and the parameter it lacks."""
    source = readme_block("tent_pcf.py").replace("class TentPCFParams(LightViewParams):", "class TentPCFParams:").replace(
        "view=p.view", "view=\"fitted\"").replace('name = "tent_pcf"', 'name = "flat_pcf"')
    install(site, "wsoft-flat-pcf", "flat_pcf", source, {"flat_pcf": "flat_pcf:TentPCF"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        techniques = reload_plugins()
    lines = [str(w.message) for w in caught if issubclass(w.category, PluginWarning)]
    assert len(lines) == 1 and "flat_pcf = flat_pcf:TentPCF" in lines[0] and "lacks the parameter cube" in lines[0]
    assert "LightViewParams" in lines[0] and "flat_pcf" in techniques
    sys.modules.pop("flat_pcf", None)
