"""USD stage -> :class:`wsoft.scene.types.Scene`.

Reads any file usd-core opens (.usda/.usdc/.usdz, sublayers, references, payloads,
variant selections, instances through instance proxies) at one time code.
Problems with the input raise :class:`SceneError` naming the file and the prim;
features that are ignored become warnings on the scene. The stage's UsdRender settings are read
first (:mod:`wsoft.scene.render_settings`): their ``includedPurposes`` decide which prims load.
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

import wsoft.usd_scenes as usd_scenes
from wsoft.errors import ParameterError, SceneError
from wsoft.scene.shapes import not_drawn, shape_type
from wsoft.scene.soup import Soup
from wsoft.scene.subdiv import check_level
from wsoft.scene.types import Scene, SkippedLight
from wsoft.scene.usd_context import MATERIAL_PURPOSES, StageContext, pxr
from wsoft.scene.usd_instancing import InstanceBuilder, InstanceReader, light_linking_instances
from wsoft.scene.usd_lights import (
    EMITS_NOTHING, HANDLED_LIGHTS, UNHANDLED_REASONS, emission_refusal, read_camera, read_light, read_shadow_controls,
)
from wsoft.scene.usd_mesh import MeshReader
from wsoft.scene.usd_time import static_geometry

__all__ = ["diagnostic_lines", "load_scene", "open_stage", "stage_file", "static_geometry", "with_views_at"]


def load_scene(path_or_stage, time: float | None = None, render_settings: str | None = None, instancing: bool = False,
               subdiv_level: int = 0, material_purpose: str = "full") -> Scene:
    """Load a USD stage (a file path, a bundled stage's name such as ``"multi_light"``, or an open
    ``Usd.Stage``) at ``time``. A name without a folder that is not an existing file is the bundled
    stage of that name (:func:`wsoft.usd_scenes.resolve`; an unknown one is an error suggesting the
    closest names).

    ``time=None`` uses the stage's start time code when it has an authored time range, else the
    earliest time sample authored on the stage (a warning names it: a stage whose values are only
    time samples has none at the default time), else the default time; ``Scene.time`` is the
    time code loaded (None: the default time). A ``Usd.Stage`` keeps its load rules and population
    mask: the scene holds the stage, and loads it again from it (other render settings,
    :meth:`Scene.flattened <wsoft.scene.types.Scene.flattened>`, :func:`wsoft.bake`), never from its file. ``render_settings``: the path of the ``RenderSettings`` prim to use;
    None picks the stage's own (metadata ``renderSettingsPrimPath``, else
    ``UsdRender.Settings.GetStageRenderSettings``; see :mod:`wsoft.scene.render_settings`). The
    settings' ``includedPurposes`` decide which purposes are loaded (without settings:
    ``default`` and ``render``, never ``proxy`` or ``guide``); the rest of them are kept on
    ``Scene.render_settings`` for the render. Returns a :class:`Scene` with world-space triangles. USD's own
    diagnostics while opening (a missing sublayer, reference or ``.mtlx``) become one
    ``warning`` line each on the scene, naming the layer; a file USD cannot parse is an error
    carrying the parser's own ``file:line:col`` message.

    ``instancing``: False (the default) flattens instanced geometry into the triangle soup, one copy
    of a prototype's meshes per instance. True keeps it instanced in ``Scene.instances``
    (:class:`~wsoft.scene.types.Instances`), each prototype's meshes read once in its own frame:

    - a ``UsdGeom.PointInstancer`` (not one inside another's prototype: that one is ignored with a
      warning, as when flat) places its prototypes (each read in its root's frame, its root's own
      transform in the instance's) with one instance per id its ``invisibleIds`` and inactive ids
      leave shown; the same checks and errors as when flat;
    - an instanceable prim (``IsInstance()``) places its USD prototype (read through the first
      instance's proxies, in the instance prim's frame; nested instances inside it are flattened
      into it). Material bindings and purposes resolve on each instance's proxies (they may come
      from above the instance): an instance whose meshes resolve to other materials, or to another
      set of meshes of an included purpose, gets a prototype of its own. An instanceable prim that
      is itself a mesh, light or camera, or whose prototype holds a light, a camera or a
      PointInstancer, is read as when flat (its meshes go to the soup; a PointInstancer inside is
      kept instanced);
    - ``Scene.prims`` names the prototype meshes (a PointInstancer prototype's mesh path; the first
      instance's proxy path) and the instance prims (the instanceable prim, the PointInstancer),
      with empty ``prim_points`` rows; the soup may be empty.

    A stage with no instances gives the flat scene (``instances`` None). A shadow-casting light
    whose ``collection:shadowLink`` leaves out any caster of a stage with instances gives the flat
    load, with a warning (per-instance shadow linking is not kept instanced).
    :meth:`Scene.flattened <wsoft.scene.types.Scene.flattened>` loads the flat scene on demand.

    ``subdiv_level``: 0 (the default) reads a subdivision surface (``subdivisionScheme``
    catmullClark, loop or bilinear, and catmullClark when unauthored: USD's fallback) as its
    control cage, with one line in ``Scene.notes`` per stage saying how many meshes that is;
    1 to 4 refines them that many times (:mod:`wsoft.scene.subdiv`: creases, corners,
    ``interpolateBoundary`` and holes honoured), each level with 4x the faces, and a note says how
    many faces that made. ``Scene.subdiv_level`` keeps it for loads of the same stage again.

    ``material_purpose``: ``full`` (the default: a renderer's final frames) resolves each prim's
    material binding for the ``full`` purpose, ``preview`` for the ``preview`` purpose; a prim with
    no binding of that purpose takes its all-purpose binding (``material:binding``), as
    ``UsdShade.MaterialBindingAPI.ComputeBoundMaterial`` resolves it. ``Scene.material_purpose``
    keeps it for loads of the same stage again.
    """
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    from pxr import UsdUtils

    delegate = UsdUtils.CoalescingDiagnosticDelegate()  # USD's warnings are collected, not printed
    if isinstance(path_or_stage, Usd.Stage):
        stage = path_or_stage
        file = stage_file(stage)
        _check_time(time, file)
        subdiv_level = _check_subdiv_level(subdiv_level, file)
        _check_material_purpose(material_purpose, file)
    else:
        file = usd_scenes.resolve(path_or_stage)
        _check_time(time, file)  # before the stage is opened
        subdiv_level = _check_subdiv_level(subdiv_level, file)
        _check_material_purpose(material_purpose, file)
        stage = open_stage(file)
    scene, linked_light = read_stage(stage, file, time, render_settings, instancing=instancing, subdiv_level=subdiv_level,
                                     material_purpose=material_purpose)
    if linked_light is not None:
        scene, _ = read_stage(stage, file, time, render_settings, subdiv_level=subdiv_level, material_purpose=material_purpose)
        scene.warnings.append(f"{file}: {linked_light}: collection:shadowLink leaves out casters and the stage has "
                              "instances: loaded flat (instancing off; per-instance shadow linking is not kept instanced)")
    scene.warnings[:0] = diagnostic_lines(delegate.TakeUncoalescedDiagnostics(), file)
    # what the scene was loaded from (the open stage itself, with its load rules, population mask
    # and session layer, or the file) and at which time argument: how a load with other render
    # settings (wsoft.pipeline.with_render_settings), Scene.flattened and wsoft.bake read it again
    source = stage if isinstance(path_or_stage, Usd.Stage) else file
    scene.__dict__["_loaded_from"] = (source, time)
    if instancing:  # how Scene.flattened loads the stage again, flat
        scene.__dict__["_source"] = functools.partial(load_scene, source, time=time, render_settings=render_settings, instancing=False,
                                                      subdiv_level=subdiv_level, material_purpose=material_purpose)
    return scene


def open_stage(file: str):
    """``Usd.Stage.Open(file)``, its problems as a :class:`SceneError` naming the file (not found, a
    folder, the parser's own ``file:line:col`` message). ``file`` may name a bundled stage
    (:func:`wsoft.usd_scenes.resolve`)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    file = usd_scenes.resolve(file)
    if not os.path.exists(file):
        raise SceneError("file not found", file=file)
    if os.path.isdir(file):
        raise SceneError("is a folder, not a USD file", file=file)
    try:
        stage = Usd.Stage.Open(file)
    except Exception as exc:  # Tf.ErrorException: the parser's own message is the useful one
        raise SceneError(f"cannot open USD stage: {_usd_error_detail(str(exc))}", file=file) from None
    if stage is None:
        raise SceneError("cannot open USD stage", file=file)
    return stage


def stage_file(stage) -> str:
    """How errors and scenes name a stage: its root layer's file, else its identifier (in memory)."""
    return stage.GetRootLayer().realPath or stage.GetRootLayer().identifier


def _check_time(time: float | None, file: str) -> None:
    if time is not None and not math.isfinite(float(time)):
        raise SceneError(f"time code {time} is not a finite number", file=file)


def _check_subdiv_level(level, file: str) -> int:
    try:
        return check_level(level)
    except ValueError as exc:
        raise ParameterError(str(exc), file=file) from None


def _check_material_purpose(purpose, file: str):
    if purpose not in MATERIAL_PURPOSES:
        raise ParameterError(f"material_purpose {purpose!r} is not one of {', '.join(MATERIAL_PURPOSES)}", file=file)


def _usd_error_detail(text: str) -> str:
    """The useful part of a ``Tf.ErrorException``: the quoted messages of its ``Error in ...`` lines,
    the parser's ``file:line:col: ...`` first, without the generic 'Failed to open layer'."""
    import re

    msgs = [m.strip() for m in re.findall(r"Error in '[^']*' at line \d+ in file [^:]+ : '(.*?)'\s*(?=\n\s*Error in|\Z)", text, re.S)]
    msgs = [m for m in msgs if m and not m.startswith("Failed to open layer")] or msgs
    if not msgs:
        lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
        return lines[0] if lines else "unreadable"
    return re.sub(r"pxrInternal_\w+?::(\w+::)*", "", " ".join(msgs[0].split()))


def diagnostic_lines(diagnostics, file: str) -> list[str]:
    """USD's diagnostics as one line each: the commentary without USD's ``(instantiating stage ...)`` tail."""
    import re

    out = []
    for d in diagnostics:
        msg = re.sub(r"\s*\(instantiating stage on stage @[^@]*@ <0x[0-9a-f]+>\)\s*$", "", " ".join(str(d.commentary).split()))
        line = f"{file}: USD: {msg}"
        if msg and line not in out:
            out.append(line)
    return out


def _passed_over(ctx, prim, it) -> bool:
    """Is ``prim`` left out of the load: invisible (its subtree pruned from the traversal ``it``) or
    of a purpose the render settings leave out (a PointInstancer's prototypes pruned with it, since
    they are drawn only where it places them; otherwise not pruned: a descendant may author a
    purpose of its own that is included)?"""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    if not prim.IsA(UsdGeom.Imageable):
        return False
    img = UsdGeom.Imageable(prim)
    if img.ComputeVisibility(ctx.timecode) == UsdGeom.Tokens.invisible:
        it.PruneChildren()
        return True
    if img.ComputePurpose() not in ctx.purposes:
        if prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()
        return True
    return False


def _dark_light_notes(file: str, skipped) -> list[str]:
    """One note per light skipped for emitting nothing."""
    return [f"{file}: {s.path}: {s.kind} skipped, it {s.reason}" for s in skipped if s.reason.startswith(EMITS_NOTHING)]


def _read_view_prim(ctx, prim, type_name: str, lights, unshadowed, skipped, cameras, shadow_lights) -> None:
    """A light or camera prim into its list (anything else: nothing)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    if type_name in HANDLED_LIGHTS:
        light = read_light(ctx, prim, type_name)
        if light is None:
            return
        dark = emission_refusal(light)
        if dark:  # nothing to shadow: listed with the skipped lights, and a note
            skipped.append(SkippedLight(str(prim.GetPath()), type_name, dark))
            return
        enabled = UsdLux.ShadowAPI(prim).GetShadowEnableAttr().Get(ctx.timecode)
        (unshadowed if enabled is False else lights).append(light)
        if enabled is not False:
            shadow_lights.append((prim, light))
    elif prim.HasAPI(UsdLux.LightAPI) or type_name.endswith("Light"):
        reason = UNHANDLED_REASONS.get(type_name, f"{type_name or 'this light'} is not handled")
        skipped.append(SkippedLight(str(prim.GetPath()), type_name or "light", reason))
        line = (f"{ctx.file}: {prim.GetPath()}: {type_name or 'light'} skipped ({reason}): it adds no light and casts no shadow "
                "in any technique or the reference; `wsoft plan` lists the lights used")
        if line not in ctx.warnings:
            ctx.warnings.append(line)
    elif prim.IsA(UsdGeom.Camera):
        cameras.append(read_camera(ctx, prim))


def _finish_views(ctx, stage, cameras, shadow_lights, prims):
    """The render settings' camera (added when the traversal passed it over) and the shadow-casting
    lights' UsdLux shadow controls (their links resolved against ``prims``); the render settings."""
    rs = ctx.render_settings
    if rs is not None and rs.camera and all(c.path != rs.camera for c in cameras):
        cameras.append(read_camera(ctx, stage.GetPrimAtPath(rs.camera)))  # hidden or of an excluded purpose: still the view
    for lp, light in shadow_lights:
        read_shadow_controls(ctx, lp, light, prims)
    return rs


def with_views_at(scene: Scene, stage, time: float | None, render_settings: str | None = None) -> Scene:
    """``scene`` (a triangle soup, no instances kept, loaded from ``stage``, whose geometry
    :func:`static_geometry` says is not animated) with its lights, cameras and render settings read
    at ``time``: its geometry and what was built from it (the device copy, bounds, caster points)
    kept. One traversal that reads no mesh."""
    if scene.instanced:
        raise ValueError("with_views_at keeps a triangle soup; a scene with instances is loaded again")
    import dataclasses

    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    file = scene.path
    ctx = StageContext(stage, file, time, render_settings)
    lights, unshadowed, skipped, cameras, shadow_lights = [], [], [], [], []
    it = iter(Usd.PrimRange.Stage(stage, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in it:
        if _passed_over(ctx, prim, it):
            continue
        if prim.IsA(UsdGeom.Gprim) or prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()
            continue
        _read_view_prim(ctx, prim, prim.GetTypeName(), lights, unshadowed, skipped, cameras, shadow_lights)
    rs = _finish_views(ctx, stage, cameras, shadow_lights, scene.prims)
    warnings = list(scene.warnings) + [w for w in ctx.warnings if w not in scene.warnings]  # the lights' and cameras' own at this time too
    notes = [n for n in scene.notes if EMITS_NOTHING not in n] + _dark_light_notes(file, skipped)
    out = dataclasses.replace(scene, lights=lights, unshadowed_lights=unshadowed, skipped_lights=skipped, cameras=cameras, time=ctx.time,
                              render_settings=rs, render_settings_source=ctx.render_settings_source, warnings=warnings, notes=notes)
    for k in ("_device_cache", "bounds", "caster_points", "_adjacency", "_dynamic_subset"):
        if k in scene.__dict__:
            out.__dict__[k] = scene.__dict__[k]
    out.__dict__["_loaded_from"] = (stage, time)
    return out


def read_stage(stage, file: str, time: float | None, render_settings: str | None = None, instancing: bool = False, subdiv_level: int = 0,
               material_purpose: str = "full"):
    """The :class:`Scene` of ``stage`` (named ``file``) at ``time``, and with ``instancing`` the first
    shadow-casting light whose ``collection:shadowLink`` an instanced load cannot keep (None: none,
    or a flat load): one traversal with instance proxies, invisible prims and their subtrees
    skipped, prims of a purpose the render settings leave out skipped (their descendants still
    visited). Meshes and UsdGeom's shapes (tessellated, :mod:`wsoft.scene.shapes`) go to the soup
    (:class:`~wsoft.scene.soup.Soup`) or, kept instanced, to the instances
    (:mod:`wsoft.scene.usd_instancing`); other gprims (curves, points, NURBS) are warned about and
    cast nothing; lights and cameras go to their lists (:mod:`wsoft.scene.usd_lights`); subdivision
    surfaces are refined ``subdiv_level`` times (0: their cages), with a note
    (:meth:`MeshReader.subdivision_note <wsoft.scene.usd_mesh.MeshReader.subdivision_note>`);
    material bindings resolve for ``material_purpose`` (:class:`StageContext`)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
    ctx = StageContext(stage, file, time, render_settings, material_purpose)
    meshes = MeshReader(ctx, subdiv_level)
    instancers = InstanceReader(ctx, meshes)
    soup = Soup()
    prims, prim_points = [], []  # every prim the scene names; its points in the soup ((0, 0): none there)
    lights, unshadowed, skipped, cameras, shadow_lights = [], [], [], [], []
    inst = InstanceBuilder(prims, prim_points) if instancing else None

    def add_mesh(mesh, name: str):
        prims.append(name)
        prim_points.append(soup.add(mesh, len(prims) - 1))

    it = iter(Usd.PrimRange.Stage(stage, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in it:
        if inst is not None and prim.IsInstance() and instancers.read_instance(prim, inst):
            it.PruneChildren()  # its prototype is placed, not flattened
            continue
        if _passed_over(ctx, prim, it):
            continue
        type_name = prim.GetTypeName()
        if prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()  # its prototypes are drawn only where it places them
            if inst is not None:
                instancers.read_instancer_instances(prim, inst)
                continue
            for mesh, name in instancers.read_instancer(prim):
                add_mesh(mesh, name)
        elif prim.IsA(UsdGeom.Mesh) or shape_type(prim):
            mesh = meshes.read(prim)
            if mesh is None:
                continue
            add_mesh(mesh, str(prim.GetPath()))
        elif prim.IsA(UsdGeom.Gprim):
            ctx.warn(prim, not_drawn(type_name))
        else:
            _read_view_prim(ctx, prim, type_name, lights, unshadowed, skipped, cameras, shadow_lights)

    rs = _finish_views(ctx, stage, cameras, shadow_lights, prims)
    linked_light = light_linking_instances(shadow_lights, inst) if inst is not None and inst.count else None
    scene = Scene(
        path=file,
        **soup.arrays(),
        prims=prims,
        prim_points=np.asarray(prim_points, np.int64).reshape(-1, 2),
        materials=meshes.materials,
        textures=meshes.textures,
        lights=lights,
        unshadowed_lights=unshadowed,
        skipped_lights=skipped,
        cameras=cameras,
        up_axis=str(UsdGeom.GetStageUpAxis(stage)),
        meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
        time=ctx.time,
        warnings=ctx.warnings,
        render_settings=rs,
        render_settings_source=ctx.render_settings_source,
        purposes=tuple(ctx.purposes),
        instances=inst.instances() if inst is not None and inst.count else None,
        notes=[n for n in [meshes.subdivision_note()] if n] + _dark_light_notes(file, skipped),
        subdiv_level=subdiv_level,
        material_purpose=material_purpose,
        skinned=meshes.skel.count if meshes.skel is not None else 0,
        skin_ms=round(meshes.skel.seconds * 1e3, 3) if meshes.skel is not None else 0.0,
    )
    return scene, linked_light
