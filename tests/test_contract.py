"""Contracts every registered technique keeps (run over ``TECHNIQUES``, not a hand-written list;
``tests/test_plugins.py`` runs the same checks on a plugin): its manual matches its ``Params``,
unknown keys and out-of-range values are rejected, its quick parameters and quality settings are
valid, the passes it adds are the ones it declares, ``supports`` agrees with ``wsoft plan`` and
``render``, its output is finite on every bundled scene it supports, it comes within its declared
tolerance of the exact parallel-rectangle answer, it never edits a resource another pass wrote,
and the README's technique table is the one the code generates."""

from __future__ import annotations

import ast
import re
import dataclasses
import importlib
import math
import pathlib
import typing

import numpy as np
import pytest
from conftest import DISTANT_ONLY, SKY_ONLY, box_plane_ground_error, scene_path

import wsoft
from wsoft import usd_scenes
from wsoft.stages import add_camera, add_point_light, add_quad, add_rect_light, make_stage
from wsoft.techniques import TECHNIQUES, create, markdown_table

NAMES = sorted(TECHNIQUES)
ROOT = pathlib.Path(__file__).resolve().parents[1]


def numeric_fields(cls):
    hints = typing.get_type_hints(cls.Params)
    return [f for f in dataclasses.fields(cls.Params) if hints[f.name] in (int, float)]


@pytest.mark.parametrize("name", NAMES)
def test_manual_matches_params(name):
    check_manual(name)


def check_manual(name):
    cls = TECHNIQUES[name]
    d = cls.describe()
    fields = [f.name for f in dataclasses.fields(cls.Params)]
    assert [p["name"] for p in d["parameters"]] == fields
    assert cls.summary and all(p["meaning"] for p in d["parameters"])
    for f in numeric_fields(cls):  # every number declares a meaningful range holding its default
        lo, hi = f.metadata["range"]
        assert lo <= f.default <= hi and lo > -math.inf, f.name
        if isinstance(f.default, float):
            assert math.isfinite(lo) and (math.isfinite(hi) or f.name == "budget"), f.name
    for f in fields:  # the class docstring (the manual) lists every parameter
        assert f"| `{f}` |" in cls.__doc__
    # a parameter table written into the module docstring by hand would drift: none is left
    mod = importlib.import_module(cls.__module__)
    assert "| parameter |" not in (mod.__doc__ or "")
    for q in cls.quality:
        assert q.param in fields and len(q.values) >= 2


@pytest.mark.parametrize("name", NAMES)
def test_unknown_keys_and_bad_values_rejected(name):
    check_bad_values(name)


def check_bad_values(name):
    cls = TECHNIQUES[name]
    with pytest.raises(wsoft.ParameterError, match="has no parameter no_such_thing"):
        create(name, {"no_such_thing": 1})
    for f in numeric_fields(cls):
        lo, hi = f.metadata["range"]
        bad = [lo - 1] + ([hi + 1] if math.isfinite(hi) else [])
        if isinstance(f.default, float):
            bad += [float("nan")] + ([float("inf")] if math.isfinite(hi) else [])
        for v in bad:
            with pytest.raises(wsoft.ParameterError, match=f.name):
                create(name, {f.name: v})


@pytest.mark.parametrize("name", NAMES)
def test_quality_settings_are_valid(name):
    check_settings(name)


def check_settings(name):
    cls = TECHNIQUES[name]
    assert cls.declaration_problem() is None
    settings = cls.quality_settings()
    assert settings[0] == {} and len(settings) == len({str(s) for s in settings})
    for s in settings:
        create(name, s)
    create(name, cls.quick_params)
    if cls.size_param:
        create(name, {cls.size_param: 512, **cls.quick_params})


@pytest.mark.parametrize("name", NAMES)
def test_passes_are_the_declared_ones(name):
    check_passes(name)


def check_passes(name, scenes=("box_plane.usda", "cutout.usda")):
    """On a plain and a cutout scene, at its quick settings and each quality setting: every pass the
    technique adds is of a declared stage (the graph checks its inputs and outputs against the
    declaration), every stage declared to run always ran, and ``wsoft techniques`` prints them."""
    from wsoft.pipeline import build_graph

    cls = TECHNIQUES[name]
    seen = set()
    for scene_name in scenes:
        scene = wsoft.load_scene(scene_path(scene_name))
        for q in cls.quality_settings():
            built = build_graph(scene, create(name, {**cls.quick_params, **q}), width=24, height=18, device="cpu", strict=False)
            label = built.labels[0]
            if label not in built.channels:
                continue
            mine = [p for p in built.ctx.graph.schedule([built.channels[label]]) if p.technique in (label, "") and p.kind in ("technique", "reference")]
            stages = {p.stage for p in mine}
            assert {s.stage for s in cls.passes if not s.when} <= stages, (name, scene_name, q, stages)
            seen |= stages
    assert seen <= {s.stage for s in cls.passes}
    d = cls.describe()
    assert [p["stage"] for p in d["passes"]] == [s.stage for s in cls.passes]
    assert "visibility" in d["writes"] and not set(d["reads"]) & set(d["writes"])


def test_the_declaration_check_can_fail():
    """A technique whose pass reads a resource its declaration leaves out, or adds a pass of a stage
    it does not declare, stops the graph's construction with a one-line error naming both."""
    from wsoft.errors import DeclarationError
    from wsoft.pipeline import build_graph
    from wsoft.techniques import PassSpec

    hard = TECHNIQUES["hard"]

    class Liar(hard):
        name = "liar"
        passes = (PassSpec("shadow", reads=("gbuffer",), writes=("visibility",)),)

    class Stranger(hard):
        name = "stranger"
        passes = (PassSpec("filter", reads=("gbuffer", "light_depth"), writes=("visibility",)),)

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    with pytest.raises(DeclarationError, match=r"pass 'hard\[Light\]' reads gbuffer, light_depth .* declares shadow: gbuffer -> visibility"):
        build_graph(scene, Liar(Liar.make_params({})), width=8, height=8)
    with pytest.raises(DeclarationError, match="adds a pass of stage 'shadow', which it does not declare"):
        build_graph(scene, Stranger(Stranger.make_params({})), width=8, height=8)


def _two_lights():
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 5)
    add_quad(st, "/World/O", (0, 0, 1), 0.5)
    add_point_light(st, "/World/Point", (0.5, 0, 3))
    add_rect_light(st, "/World/Rect", (-0.5, 0, 3), 1, 1)
    add_camera(st, "/World/Cam", (0, -4, 4), (0, 0, 0))
    return wsoft.load_scene(st)


def test_supports_agrees_with_plan_and_render():
    scene = _two_lights()
    plan = wsoft.plan(scene)
    assert set(plan["techniques"]) == set(NAMES) - SKY_ONLY - DISTANT_ONLY  # every other technique supports the rect light
    for name in NAMES:
        tech = create(name)
        declined = {l.path: tech.supports(scene, l) for l in scene.lights if tech.supports(scene, l) is not None}
        listed = {w["light"]: w["reason"] for w in plan["not_applicable"].get(name, [])}
        assert listed == declined, name
        if name in SKY_ONLY | DISTANT_ONLY:
            assert set(declined) == {l.path for l in scene.lights}, name
            continue
        if tech.point_refusal:  # a technique's own reason for point lights is the one given
            assert declined.get("/World/Point") == tech.point_refusal, name
        f = wsoft.render(scene, name, width=24, height=18, device="cpu", **({"samples": 4} if name == "reference" else {}))
        assert f.stats["lights"] == [l.path for l in scene.lights if l.path not in declined]
        assert all(any(p in w for w in f.stats["warnings"]) for p in declined)
        if declined:
            with pytest.raises(wsoft.ParameterError, match=re.escape(next(iter(declined.values()))[:30])):
                wsoft.render(scene, name, width=8, height=8, device="cpu", light="/World/Point")
    assert "ssm" in plan["not_applicable"]  # the interesting case happened: ssm declines the point light
    assert {n for n in NAMES if create(n).point_refusal} >= {"dcs", "pwedge"}


def test_plan_lists_a_point_light_instead_of_failing(tmp_path):
    """``wsoft plan`` on a stage with a point light lists ssm as not applicable, with the reason."""
    from conftest import wsoft_cli

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 5)
    add_point_light(st, "/World/L", (0, 0, 3))
    path = tmp_path / "point.usda"
    st.GetRootLayer().Export(str(path))
    p = wsoft_cli("plan", str(path))
    assert p.returncode == 0, p.stderr
    assert "ssm: not applicable to /World/L: the light has no area" in p.stdout
    assert "hard: upload_scene -> gbuffer" in p.stdout


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", usd_scenes.names())
def test_finite_on_every_bundled_scene(scene_name):
    """Every technique, on every light of every bundled stage it supports: finite, in [0, 1]."""
    from wsoft.errors import ParameterError
    from wsoft.pipeline import load_stage
    from wsoft.pipeline.build import refusal
    from wsoft.pipeline.loading import too_big_to_flatten

    scene = load_stage(str(usd_scenes.path(scene_name)))  # as the command line loads it (forest keeps its instances)
    for name in NAMES:
        params = TECHNIQUES[name].quick_params
        lights = [l for l in scene.lights if refusal((name, params), scene, l, width=32, height=24) is None]
        if not lights:
            with pytest.raises(ParameterError):  # it renders none of the stage's lights: an error saying why, never a frame left lit
                wsoft.render(scene, name, width=32, height=24, device="cpu", **params)
            continue
        if scene.instanced and create(name, params).instancing_why() and too_big_to_flatten(scene):
            with pytest.raises(ParameterError, match="needs the stage flattened"):
                wsoft.render(scene, name, width=32, height=24, device="cpu", **params)
            continue
        f = wsoft.render(scene, name, width=32, height=24, device="cpu", **params)
        for ch in [k for k in f.channels if k.startswith("V")]:
            v = f[ch]
            assert np.all(np.isfinite(v)) and v.min() >= 0.0 and v.max() <= 1.0, (name, ch)


@pytest.mark.parametrize("name", NAMES)
def test_within_declared_tolerance_of_the_exact_answer(device, name):
    check_tolerance(name, device)


def check_tolerance(name, device="cpu"):
    """box_plane: a square occluder parallel to a square light and the ground, at default parameters."""
    if name in SKY_ONLY:
        pytest.skip(f"{name} shadows a DomeLight alone, not box_plane's rect light")
    if name in DISTANT_ONLY:
        pytest.skip(f"{name} shadows DistantLights alone, not box_plane's rect light")
    tol = TECHNIQUES[name].tolerance
    assert tol is not None, f"{name} declares no tolerance"
    f = wsoft.render(wsoft.load_scene(scene_path("box_plane.usda")), name, width=128, height=96, device=device)
    mae, mae_pen, _ = box_plane_ground_error(f)
    assert mae <= tol.mae and mae_pen <= tol.mae_penumbra, f"{name}: MAE {mae:.4f} (<= {tol.mae}), penumbra {mae_pen:.4f} (<= {tol.mae_penumbra})"


@pytest.mark.parametrize("name", NAMES)
def test_no_pass_edits_another_pass_resource(name):
    check_immutable(name)


def check_immutable(name):
    from wsoft.pipeline import build_graph, execute

    scene = wsoft.load_scene(scene_path("contact.usda"))
    if name in SKY_ONLY:  # a stage under a constant sky
        scene = wsoft.load_scene(scene_path("dome_uniform.usda"))
    if name in DISTANT_ONLY:  # the same stage under a sun
        from wsoft.scene.types import LIGHT_DISTANT, Light

        scene.lights[:] = [Light(path="/World/Sun", kind=LIGHT_DISTANT, position=np.zeros(3), frame=np.eye(3), angle_deg=2.0)]
    params = TECHNIQUES[name].quick_params
    built = build_graph(scene, create(name, params), width=32, height=24, device="cpu", pixel_samples=2 if name == "ssm" else 1)
    execute(built, "cpu", check_immutable=True)  # raises if a pass changed an input


def test_the_immutability_check_can_fail():
    from wsoft.graph import FrameGraph, Key, Pass

    g = FrameGraph()
    a, b = Key("a"), Key("b")
    g.add(Pass("make", (), (a,), lambda res: {a: np.zeros(3)}, kind="scene"))

    def bad(res):
        res[a][0] = 1.0
        return {b: np.ones(1)}

    g.add(Pass("edit", (a,), (b,), bad, kind="technique"))
    with pytest.raises(RuntimeError, match="modified 'a', written by 'make'"):
        g.execute([b], "cpu", keep=[a], check_immutable=True)


def test_readme_technique_table_is_generated_from_the_code():
    """``wsoft techniques --markdown`` wrote the README's table (regenerate it when this fails)."""
    readme = (ROOT / "README.md").read_text()
    begin, end = "<!-- techniques:begin (wsoft techniques --markdown) -->", "<!-- techniques:end -->"
    assert begin in readme and end in readme
    table = readme.split(begin, 1)[1].split(end, 1)[0].strip()
    assert table == markdown_table()
    assert "| `ssm` |" in table


def test_every_technique_is_registered():
    """Every class under wsoft/techniques that declares a technique ``name`` is registered, under the
    name of the module (or package) that holds it: the registry needs no list of its own."""
    found = {}
    for path in (ROOT / "wsoft" / "techniques").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                for stmt in node.body:
                    if isinstance(stmt, ast.Assign) and ast.unparse(stmt.targets[0]) == "name":
                        rel = path.relative_to(ROOT / "wsoft" / "techniques")
                        found[ast.literal_eval(stmt.value)] = rel.parts[0].removesuffix(".py")
    assert len(found) >= 13 and all(name == module for name, module in found.items()), found
    bundled = {n for n, c in TECHNIQUES.items() if c.__module__.startswith("wsoft.techniques.")}
    assert set(found) == bundled == set(wsoft.techniques.bundled_names())
