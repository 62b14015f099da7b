"""``wsoft plan``: what a render would run on a stage, without running it (the lights and their
UsdLux shadow controls, skipped lights, cutouts, the framing, and per technique its passes or why
it is not applicable to a light)."""

from __future__ import annotations

import math

import numpy as np

from wsoft.lightspace.cube import CUBE_KINDS, outside_view_remedy
from wsoft.lightspace.fit import local_axes
from wsoft.lightspace.view import MAX_HALF_ANGLE, to_frame
from wsoft.pipeline.build import build_graph
from wsoft.pipeline.framing import frame_setup
from wsoft.pipeline.loading import instancing_plan, load_stage, too_big_to_flatten
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISTANT, LIGHT_DOME, Light, Scene


COLOR_APPLIED = "applied to R G B, not to V"
FALLOFF_APPLIED = "not applied (UsdLux gives no formula for the fade; the shadow ends sharply at shadow:distance)"


def shadow_controls(scene: Scene, light: Light) -> dict:
    """A light's UsdLux shadow controls as ``wsoft plan`` lists them: the ``collection:shadowLink``
    membership (prims it leaves out of the shadow, of the prims loaded), ``inputs:shadow:distance``
    (None: unlimited) and which of the techniques that render the light honour it, the shadow colour (applied to ``R G B``, not
    to ``V``) and falloff (not applied)."""
    from wsoft.techniques import TECHNIQUES

    out = [scene.prims[i] for i in light.shadow_excluded]
    casting = scene.casting_mask(light)
    refused = sorted(n for n, c in TECHNIQUES.items() if c.distance_refusal)
    if light.distance_limited:  # among the techniques that render this light at all (without the distance)
        import dataclasses

        unlimited = dataclasses.replace(light, shadow_distance=-1.0)
        renders = {n for n, c in TECHNIQUES.items() if c(c.make_params({})).supports(scene, unlimited) is None}
        refused = [n for n in refused if n in renders]
    else:
        renders = set(TECHNIQUES)
    return {
        "link": {"excluded_prims": len(out), "prims": len(scene.prims), "excluded": out[:5],
                 "casting_triangles": scene.triangle_count if casting is None else int(casting.sum()),
                 "applied": "excluded prims cast no shadow of this light (still seen, still receive it)" if out else "every prim casts"},
        "distance": light.shadow_distance if light.distance_limited else None,
        "distance_applied": ("unlimited" if not light.distance_limited else
                             f"honoured by {', '.join(n for n in sorted(renders) if n not in refused)}; refused by {', '.join(refused)}"),
        "color": list(light.shadow_color),
        "color_applied": COLOR_APPLIED,
        "falloff": light.shadow_falloff,
        "falloff_gamma": light.shadow_falloff_gamma,
        "falloff_applied": FALLOFF_APPLIED if light.shadow_falloff > 0 else "none authored (falloff <= 0)",
    }


def emission(scene: Scene, light: Light) -> dict:
    """Where a light emits, as ``wsoft plan`` lists it: ``side`` (``front``: a rect or disk light,
    from its front only, along ``direction``, its transformed local −Z; ``all around``: a sphere or
    point light; ``along``: a distant light's ``direction``; ``from the sky``: a dome; ``shaped``: a ``UsdLux.ShapingAPI`` cone
    of ``cone`` degrees off ``direction``, its ``softness``, ``focus`` and ``focus_tint``) and, for a one-sided light, how many of
    the scene's mesh points (:attr:`Scene.caster_points`) lie on or behind its plane, where it gives
    V = 0 (``points_behind`` of ``points``)."""
    d = [float(c) + 0.0 for c in np.round(np.asarray(light.direction, np.float64), 6)]
    if light.shaping.shaped:  # UsdLux ShapingAPI: emission cut to a cone about -Z and faded off axis
        return {"side": "shaped", "direction": d, "cone": light.shaping.cone_deg, "softness": light.shaping.softness, "focus": light.shaping.focus,
                "focus_tint": list(light.shaping.focus_tint), "one_sided": light.one_sided,
                "ies": ({"file": light.shaping.ies_path, "angle_scale": light.shaping.ies_angle_scale,
                         "normalize": light.shaping.ies_normalize} if light.shaping.ies is not None else None)}
    if light.one_sided:
        pts = scene.caster_points
        return {"side": "front", "direction": d, "points_behind": light.points_behind(pts), "points": int(len(pts))}
    if light.kind == LIGHT_DISTANT:
        return {"side": "along", "direction": d}
    if light.kind == LIGHT_DOME:  # the sky: inward from every direction (wsoft.scene.dome)
        return {"side": "from the sky (" + light.dome.description() + ")"}
    return {"side": "all around"}


def one_frustum_shortfalls(ctx, lights: list[Light]) -> dict[str, str]:
    """Per rect or disk light (one frustum, never a cube map) whose receivers in front of it lie
    beyond the widest frustum (:data:`~wsoft.lightspace.view.MAX_HALF_ANGLE`) in the cube-map
    decision's probe: what the shadow-map techniques leave unshadowed, and what to do (the line the
    render warns with, :func:`~wsoft.lightspace.cube.outside_view_remedy`)."""
    from wsoft.techniques import unmapped_techniques

    out = {}
    rec, probe = ctx.probe_receivers()
    for l in lights:
        v = to_frame(rec, np.asarray(l.position, np.float64), local_axes(l))  # its view's frame: z along its emitting -Z
        v = v[v[:, 2] > 0.0]
        if not len(v):
            continue
        angle = math.degrees(math.atan(float(np.max(np.maximum(np.abs(v[:, 0]), np.abs(v[:, 1])) / v[:, 2]))))
        if angle > MAX_HALF_ANGLE:
            out[l.path] = (f"one frustum, its receivers up to {angle:.0f} degrees off its axis ({probe} probe): the shadow-map "
                           f"techniques leave those beyond {MAX_HALF_ANGLE:g} unshadowed, with a warning; "
                           + outside_view_remedy(l, None, unmapped_techniques()))
    return out


def plan(scene, techniques: list[str] | None = None, *, width: int | None = None, height: int | None = None, light=None,
         camera=None, auto: dict | None = None) -> dict:
    """What would run on ``scene`` (a :class:`Scene`, or what :func:`wsoft.pipeline.load_stage` loads:
    a USD path or a bundled stage's name): the time code the scene was loaded at (``time``; None: the default time),
    shadow-casting lights (where each emits, :func:`emission`, the RGB radiance it is shaded with,
    ``radiance``: ``intensity x 2^exposure x color``, colour temperature and ``normalize`` applied,
    with their UsdLux shadow controls,
    :func:`shadow_controls`), skipped lights, cutout materials, the purposes loaded, the framing
    (``framing``: which render settings prim and camera, where each came from, the resolution,
    conform policy and data window; see :meth:`Framing.describe`), the load's warnings and notes
    (``notes``: subdivision surfaces read as their cage, or refined; ``subdiv_level``; ``warnings``
    also holds, as ``TECHNIQUE: line``, what building a technique's passes warns of, such as a
    DistantLight wider than it models), and per
    technique the passes (with their kinds) or why it is not applicable to a light, and what it
    renders of each cylinder light (``cylinder_lights``: its :attr:`~wsoft.techniques.Technique.cylinder_model`);
    for each sphere, point or cylinder light whether the shadow-map techniques draw it as one frustum or
    a cube map, and why (``light_views``, :class:`~wsoft.lightspace.cube.CubeDecision`).
    ``auto``: the parameters of technique ``auto`` (one goal: ``budget_ms``, ``target_error``, ``target_flip`` or ``target_flicker``) when
    ``techniques`` names it; ``auto`` in the plan then holds per light its choice's record
    (:meth:`wsoft.auto.choose.Choice.record`: features, candidates' predictions, choice, runner-up)."""
    from wsoft.techniques import TECHNIQUES

    if not isinstance(scene, Scene):
        scene = load_stage(scene)
    out = {
        "scene": scene.path,
        "triangles": scene.total_triangles,
        "time": scene.time,
        "instancing": instancing_plan(scene, [], []),
        "up_axis": scene.up_axis,
        "meters_per_unit": scene.meters_per_unit,
        "lights": [{"path": l.path, "kind": l.kind_name, "size": l.size_description(), "emits": emission(scene, l),
                    "radiance": [float(l.intensity * c) for c in l.color],
                    "shadow": shadow_controls(scene, l)} for l in scene.lights],
        "skipped_lights": [{"path": l.path, "kind": l.kind_name, "reason": "shadow:enable = false"} for l in scene.unshadowed_lights]
        + [{"path": s.path, "kind": s.kind, "reason": s.reason} for s in scene.skipped_lights],
        "cutout_materials": [{"path": p, "triangles": n} for p, n in scene.cutout_triangle_counts().items()],
        "dynamic_prims": scene.dynamic_prims(),
        "skinned": {"meshes": scene.skinned, "skin_ms": scene.skin_ms},
        "baked_light_triangles": 0 if scene.tri_baked is None else int(np.count_nonzero(~np.isnan(scene.tri_baked[:, 0, 0]))),
        "cameras": [c.path for c in scene.cameras],
        "purposes": list(scene.purposes),
        "framing": frame_setup(scene, width, height, camera).describe(),
        "warnings": list(scene.warnings),
        "notes": list(scene.notes),
        "subdiv_level": scene.subdiv_level,
        "techniques": {},
        "not_applicable": {},
    }
    if not scene.lights:
        return out
    for name in techniques or sorted(TECHNIQUES):
        built = build_graph(scene, (name, auto or {}) if name == "auto" else name, width=width, height=height, camera=camera, light=light,
                            device="cpu", strict=False)
        if "light_views" not in out:  # which lights get a cube map, and why (the same for every technique with cube=auto)
            chosen = [l for l in scene.lights if light is None or getattr(light, "path", light) in (l.path, l.name)]
            out["light_views"] = {l.path: built.ctx.cube_decision(l).why("auto") for l in chosen if l.kind in CUBE_KINDS}
            out["light_views"].update(one_frustum_shortfalls(built.ctx, [l for l in chosen if l.one_sided]))
        label = built.labels[0]
        if name == "auto":
            out["auto"] = {lb: c["auto"] for lb, c in built.ctx.counters["techniques"].get(label, {}).items() if "auto" in c}
        if built.instancing["mode"] == "flattened":
            why = built.instancing["needs"][0][1]
            too_big = too_big_to_flatten(scene)
            if too_big:  # render refuses it: say so instead of listing passes
                out["not_applicable"][name] = [{"light": "(every light)", "reason": f"{why}: needs the stage flattened, {too_big}"}]
                continue
            out.setdefault("flattened_for", {})[name] = why
        if built.skipped[label]:
            out["not_applicable"][name] = [{"light": l.path, "reason": why} for l, why in built.skipped[label]]
        if label in built.channels:
            out["techniques"][name] = [p.name for p in built.ctx.graph.schedule([built.channels[label]])]
            skipped = {l.path for l, _ in built.skipped[label]}
            cyl = [l.path for l in scene.lights if l.kind == LIGHT_CYLINDER and l.path not in skipped
                   and (light is None or getattr(light, "path", light) in (l.path, l.name))]
            if cyl and name in TECHNIQUES and TECHNIQUES[name].cylinder_model:
                out.setdefault("cylinder_lights", {})[name] = [{"light": c, "model": TECHNIQUES[name].cylinder_model} for c in cyl]
            out.setdefault("pass_kinds", {}).update({p.name: p.kind for p in built.ctx.graph.schedule([built.channels[label]])})
            for p in built.ctx.graph.schedule([built.channels[label]]):  # what building its passes found (a sun wider than it models)
                out["warnings"] += [f"{name}: {w}" for w in built.ctx.warnings.get(p.name, []) if f"{name}: {w}" not in out["warnings"]]
    return out
