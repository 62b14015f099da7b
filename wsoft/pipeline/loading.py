"""Loading a stage for rendering, and what a render does with its instances: kept (prototypes once)
where every technique draws and traces them as they are, else flattened for the techniques that
read the triangle soup (:func:`instancing_plan`), up to :data:`FLATTEN_LIMIT` triangles."""

from __future__ import annotations

import os

from wsoft.errors import ParameterError
from wsoft.scene.types import Scene
from wsoft.scene.usd import load_scene


INSTANCING_MODES = ("auto", "keep", "flatten")
AUTO_KEEP_TRIANGLES = 4_000_000  # instancing=auto keeps instances when they place more triangles than this


def load_stage(path, *, time: float | None = None, render_settings: str | None = None, instancing: str = "auto",
               subdiv_level: int = 0, material_purpose: str = "full") -> Scene:
    """Load a stage for rendering. ``instancing``: ``keep`` — PointInstancers and instanceable prims
    stay instances (prototypes once; techniques that read the triangle soup get it flattened by
    the frame graph, :func:`instancing_plan`); ``flatten`` — one triangle soup (every instance's
    copy); ``auto`` (default) — keep them when they place more than :data:`AUTO_KEEP_TRIANGLES`
    triangles (a stage that would not fit flattened), else flatten (the soup lets the reference
    trace in packets, faster on CPU than rays through the top level). ``subdiv_level``: how many
    times subdivision surfaces are refined (0: their control cages; see :func:`load_scene`);
    ``material_purpose``: ``full`` or ``preview``, the purpose material bindings resolve for (see
    :func:`load_scene`)."""
    if instancing not in INSTANCING_MODES:
        raise ParameterError(f"instancing {instancing!r} is not one of {', '.join(INSTANCING_MODES)}")
    if instancing == "flatten":
        return load_scene(path, time=time, render_settings=render_settings, subdiv_level=subdiv_level, material_purpose=material_purpose)
    scene = load_scene(path, time=time, render_settings=render_settings, instancing=True, subdiv_level=subdiv_level,
                       material_purpose=material_purpose)
    if instancing == "auto" and scene.instanced and scene.instances.instanced_triangles <= AUTO_KEEP_TRIANGLES:
        return scene.flattened()
    return scene


def with_render_settings(scene, render_settings: str | None, time_code: float | None = None) -> Scene:
    """``scene`` (a :class:`Scene` or what :func:`load_scene` opens) loaded with the render
    settings ``render_settings`` (None: as it is, or the stage's own). A :class:`Scene` loaded
    with other settings is loaded again from what it was loaded from: the open ``Usd.Stage``
    itself (its load rules and population mask kept), else its file, at its ``subdiv_level`` and
    ``material_purpose``."""
    if not isinstance(scene, Scene):
        return load_stage(scene, time=time_code, render_settings=render_settings)
    if render_settings is None:
        return scene
    have = scene.render_settings.path if scene.render_settings is not None else None
    if have == str(render_settings):
        return scene
    source, time = scene.__dict__.get("_loaded_from", (None, scene.time))
    if source is not None and (not isinstance(source, str) or os.path.isfile(source)):  # the settings' includedPurposes may change the geometry
        return load_scene(source, time=time, render_settings=str(render_settings), subdiv_level=scene.subdiv_level,
                          material_purpose=scene.material_purpose)  # an open stage as it is
    if os.path.isfile(scene.path):
        return load_scene(scene.path, time=scene.time, render_settings=str(render_settings), subdiv_level=scene.subdiv_level,
                          material_purpose=scene.material_purpose)
    raise ParameterError(f"this scene was loaded with render settings {have or '(none)'} and has no file to load again; "
                         f"pass render_settings={str(render_settings)!r} to load_scene", file=scene.path)


FLATTEN_LIMIT = 4_000_000
"""Instanced triangles beyond which a stage is not flattened for a technique that needs it (the
one-line error names the techniques that keep instances). Flattening a loaded stage peaks near
3.3 kB a triangle (``wsoft bench scaling``'s instances axis: 6.8 GB at 2.09M triangles), and
dcs on open_world's 6.0M flattened ran out of 24 GiB: at this limit the flat copy stays near
13 GB. The same bound as :data:`AUTO_KEEP_TRIANGLES`: a stage too big to flatten by default is
not flattened for one technique either."""


def instancing_plan(scene: Scene, techs: list, labels: list[str]) -> dict:
    """How ``scene``'s instances are drawn for ``techs``: ``mode`` ``none`` (the stage has none),
    ``kept`` (every technique keeps them: prototypes once, :mod:`wsoft.scene.instancing`) or
    ``flattened`` (a technique reads the triangle soup: ``needs`` lists (label, reason))."""
    if not scene.instanced:
        return {"mode": "none"}
    inst = scene.instances
    needs = [(label, t.instancing_why()) for t, label in zip(techs, labels) if t.instancing_why()]
    return {"mode": "flattened" if needs else "kept", "needs": needs, "instances": inst.count, "prototypes": len(inst.prototypes),
            "prototype_triangles": inst.prototype_triangles, "instanced_triangles": inst.instanced_triangles,
            "soup_triangles": scene.triangle_count}


def too_big_to_flatten(scene: Scene) -> str | None:
    """Why ``scene`` is not flattened (more than :data:`FLATTEN_LIMIT` triangles), else None."""
    if scene.total_triangles > FLATTEN_LIMIT:
        return f"{scene.total_triangles:,} triangles (more than {FLATTEN_LIMIT:,})"
    return None


def flatten_for(scene: Scene, plan: dict) -> Scene:
    """``scene`` flattened for the techniques of ``plan`` that read the triangle soup; an error when
    it would hold more than :data:`FLATTEN_LIMIT` triangles (name the techniques and those that keep instances)."""
    who = "; ".join(f"{label} ({why})" for label, why in plan["needs"])
    if too_big_to_flatten(scene):
        from wsoft.techniques import TECHNIQUES

        keep = ", ".join(n for n, t in sorted(TECHNIQUES.items()) if not t.instancing_refusal)
        raise ParameterError(f"{who}: needs the stage flattened, {scene.total_triangles:,} triangles from {plan['instances']:,} instances "
                             f"(more than {FLATTEN_LIMIT:,}); techniques that keep instances: {keep}", file=scene.path)
    return scene.flattened()
