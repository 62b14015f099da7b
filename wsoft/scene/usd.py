"""USD stage -> :class:`wsoft.scene.types.Scene`.

Reads any file usd-core opens (.usda/.usdc/.usdz, sublayers, references, payloads,
variant selections, instances through instance proxies) at one time code.
Problems with the input raise :class:`SceneError` naming the file and the prim;
features that are ignored become warnings on the scene. The stage's UsdRender settings are read
first (:mod:`wsoft.scene.render_settings`): their ``includedPurposes`` decide which prims load.
"""

from __future__ import annotations

import math
import os

import numpy as np

from wsoft.errors import SceneError
from wsoft.scene.render_settings import DEFAULT_PURPOSES, read_render_settings
from wsoft.scene.types import (
    LIGHT_DISK,
    LIGHT_DISTANT,
    LIGHT_POINT,
    LIGHT_RECT,
    LIGHT_SPHERE,
    WRAP_NAMES,
    Camera,
    Instances,
    Light,
    Material,
    Prototype,
    Scene,
    SkippedLight,
    Texture,
)

_HANDLED_LIGHTS = ("RectLight", "DiskLight", "SphereLight", "DistantLight")
_UNHANDLED_REASONS = {
    "DomeLight": "environment (dome) lighting has no finite emitter to shadow-map; not handled",
    "CylinderLight": "cylinder lights are not handled by any technique",
    "GeometryLight": "mesh (geometry) lights are not handled by any technique",
    "PortalLight": "portal lights only shape a DomeLight; not handled",
    "PluginLight": "plugin lights have no known shape; not handled",
}


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: F401
    except ImportError as exc:  # pragma: no cover - install problem
        raise SceneError(f"usd-core is not installed ({exc}); run `pip install usd-core`") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade


def load_scene(path_or_stage, time: float | None = None, render_settings: str | None = None, instancing: bool = False) -> Scene:
    """Load a USD stage (a file path or an open ``Usd.Stage``) at ``time``.

    ``time=None`` uses the stage's start time code when it has an authored time range,
    else the default time. ``render_settings``: the path of the ``RenderSettings`` prim to use;
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
    """
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
    from pxr import UsdUtils

    delegate = UsdUtils.CoalescingDiagnosticDelegate()  # USD's warnings are collected, not printed
    if isinstance(path_or_stage, Usd.Stage):
        stage = path_or_stage
        file = stage_file(stage)
    else:
        file = os.fspath(path_or_stage)
        _check_time(time, file)
        stage = open_stage(file)
    _check_time(time, file)
    reader = _StageReader(stage, file, time, render_settings, instancing=instancing)
    scene = reader.read()
    if reader.linked_light is not None:
        scene = _StageReader(stage, file, time, render_settings).read()
        scene.warnings.append(f"{file}: {reader.linked_light}: collection:shadowLink leaves out casters and the stage has "
                              "instances: loaded flat (instancing off; per-instance shadow linking is not kept instanced)")
    scene.warnings[:0] = diagnostic_lines(delegate.TakeUncoalescedDiagnostics(), file)
    if instancing:
        scene.__dict__["_source"] = (stage if isinstance(path_or_stage, Usd.Stage) else file, time, render_settings)
    return scene


def open_stage(file: str):
    """``Usd.Stage.Open(file)``, its problems as a :class:`SceneError` naming the file (not found, a
    folder, the parser's own ``file:line:col`` message)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
    file = os.fspath(file)
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


class _StageReader:
    def __init__(self, stage, file: str, time: float | None, render_settings: str | None = None, instancing: bool = False):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        self.stage = stage
        self.file = file
        if time is None:
            self.timecode = Usd.TimeCode(stage.GetStartTimeCode()) if stage.HasAuthoredTimeCodeRange() else Usd.TimeCode.Default()
        else:
            self.timecode = Usd.TimeCode(float(time))
        self.time = None if self.timecode.IsDefault() else float(self.timecode.GetValue())
        self.xf = UsdGeom.XformCache(self.timecode)
        self.world_override = None  # (prototype root prim, its world matrix) while reading a PointInstancer's instance
        self.instancer_dynamic = False
        self.warnings: list[str] = []
        self.materials: list[Material] = []
        self.material_index: dict[str, int] = {"": 0}
        self.materials.append(Material(path="(default)"))
        self.textures: list[Texture] = []
        self.texture_index: dict[tuple, int] = {}
        self.dynamic_cache: dict[str, bool] = {}
        self.dynamic_stop = None  # a prim is_dynamic does not walk up past (an instance prim, while reading its prototype)
        self.instancing = instancing
        self.linked_light = None  # instancing: a light whose shadowLink leaves out casters (the load is then done flat)
        self.render_settings, self.render_settings_source = read_render_settings(self, render_settings)
        self.purposes = self.render_settings.included_purposes if self.render_settings else DEFAULT_PURPOSES

    # -- helpers -----------------------------------------------------------------
    def warn(self, prim, msg: str):
        where = f"{self.file}: {prim.GetPath()}: " if prim is not None else f"{self.file}: "
        self.warnings.append(where + msg)

    def err(self, prim, msg: str) -> SceneError:
        return SceneError(msg, file=self.file, prim=str(prim.GetPath()) if prim is not None else None)

    def world(self, prim) -> np.ndarray:
        if self.world_override is not None:  # a prototype's mesh, placed by its PointInstancer
            rel, _ = self.xf.ComputeRelativeTransform(prim, self.world_override[0])
            return self.world_override[1] @ np.array(rel, dtype=np.float64).T
        m = self.xf.GetLocalToWorldTransform(prim)
        return np.array(m, dtype=np.float64).T  # column-vector convention

    def finite(self, prim, name: str, value) -> float:
        """``value`` as a float; a NaN or infinite one is an error naming the attribute."""
        v = float(value)
        if not math.isfinite(v):
            raise self.err(prim, f"{name} = {v} is not a finite number")
        return v

    def size(self, prim, name: str, value) -> float:
        """A light's size attribute: finite and >= 0."""
        v = self.finite(prim, name, value)
        if v < 0:
            raise self.err(prim, f"{name} = {v:g} is negative")
        return v

    def get(self, attr, default=None):
        if not attr or not attr.HasAuthoredValue() and attr.Get(self.timecode) is None:
            return default
        v = attr.Get(self.timecode)
        return default if v is None else v

    # -- main --------------------------------------------------------------------
    def read(self) -> Scene:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        pts, tris, tri_prim, tri_mat, tri_uv, tri_ds, tri_cl, tri_dyn, tri_bk, prims = [], [], [], [], [], [], [], [], [], []
        tri_face, prim_points = [], []
        lights, unshadowed, skipped, cameras, shadow_lights = [], [], [], [], []
        nverts = 0
        inst = _InstanceBuilder(prims, prim_points) if self.instancing else None
        it = iter(Usd.PrimRange.Stage(self.stage, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
        for prim in it:
            if inst is not None and prim.IsInstance() and self.read_instance(prim, inst):
                it.PruneChildren()  # its prototype is placed, not flattened
                continue
            if prim.IsA(UsdGeom.Imageable):
                img = UsdGeom.Imageable(prim)
                if img.ComputeVisibility(self.timecode) == UsdGeom.Tokens.invisible:
                    it.PruneChildren()
                    continue
                if img.ComputePurpose() not in self.purposes:
                    if prim.IsA(UsdGeom.PointInstancer):
                        it.PruneChildren()  # its prototypes are drawn only where it places them
                    continue  # otherwise not pruned: a descendant may author a purpose of its own that is included
            type_name = prim.GetTypeName()

            def add_mesh(mesh, name: str):
                nonlocal nverts
                p, t, m, uv, ds, closed, dynamic, baked, faces = mesh
                prims.append(name)
                prim_points.append((nverts, len(p)))
                pts.append(p)
                tris.append(t + nverts)
                nverts += len(p)
                tri_prim.append(np.full(len(t), len(prims) - 1, np.int32))
                tri_mat.append(m)
                tri_uv.append(uv)
                tri_ds.append(np.full(len(t), ds, bool))
                tri_cl.append(np.full(len(t), closed, np.int8))
                tri_dyn.append(np.full(len(t), dynamic, bool))
                tri_bk.append((baked, len(t)))
                tri_face.append(faces.astype(np.int32))

            if prim.IsA(UsdGeom.PointInstancer):
                it.PruneChildren()  # its prototypes are drawn only where it places them
                if inst is not None:
                    self.read_instancer_instances(prim, inst)
                    continue
                for mesh, name in self.read_instancer(prim):
                    add_mesh(mesh, name)
            elif prim.IsA(UsdGeom.Mesh):
                mesh = self.read_mesh(prim)
                if mesh is None:
                    continue
                add_mesh(mesh, str(prim.GetPath()))
            elif prim.IsA(UsdGeom.Gprim) and not prim.IsA(UsdGeom.Mesh):
                self.warn(prim, f"{type_name} is not a Mesh; ignored (convert it to a mesh to cast shadows)")
            elif type_name in _HANDLED_LIGHTS:
                light = self.read_light(prim, type_name)
                if light is None:
                    continue
                enabled = UsdLux.ShadowAPI(prim).GetShadowEnableAttr().Get(self.timecode)
                (unshadowed if enabled is False else lights).append(light)
                if enabled is not False:
                    shadow_lights.append((prim, light))
            elif prim.HasAPI(UsdLux.LightAPI) or type_name.endswith("Light"):
                reason = _UNHANDLED_REASONS.get(type_name, f"{type_name or 'this light'} is not handled")
                skipped.append(SkippedLight(str(prim.GetPath()), type_name or "light", reason))
            elif prim.IsA(UsdGeom.Camera):
                cameras.append(self.read_camera(prim))

        rs = self.render_settings
        if rs is not None and rs.camera and all(c.path != rs.camera for c in cameras):
            cameras.append(self.read_camera(self.stage.GetPrimAtPath(rs.camera)))  # hidden or of an excluded purpose: still the view

        for lp, light in shadow_lights:
            self.read_shadow_controls(lp, light, prims)
        if inst is not None and inst.count:
            self.linked_light = self.light_linking_instances(shadow_lights, inst)
        if pts:
            points = np.concatenate(pts).astype(np.float32)
            triangles = np.concatenate(tris).astype(np.int32)
        else:
            points = np.zeros((0, 3), np.float32)
            triangles = np.zeros((0, 3), np.int32)
        scene = Scene(
            path=self.file,
            points=points,
            triangles=triangles,
            tri_prim=np.concatenate(tri_prim) if tri_prim else np.zeros(0, np.int32),
            tri_material=np.concatenate(tri_mat).astype(np.int32) if tri_mat else np.zeros(0, np.int32),
            tri_uv=np.concatenate(tri_uv).astype(np.float32) if tri_uv else np.zeros((0, 3, 2), np.float32),
            tri_double_sided=np.concatenate(tri_ds) if tri_ds else np.zeros(0, bool),
            tri_closed=np.concatenate(tri_cl) if tri_cl else np.zeros(0, np.int8),
            tri_dynamic=np.concatenate(tri_dyn) if tri_dyn else np.zeros(0, bool),
            tri_baked=_baked(tri_bk),
            tri_face=np.concatenate(tri_face) if tri_face else np.zeros(0, np.int32),
            prims=prims,
            prim_points=np.asarray(prim_points, np.int64).reshape(-1, 2),
            materials=self.materials,
            textures=self.textures,
            lights=lights,
            unshadowed_lights=unshadowed,
            skipped_lights=skipped,
            cameras=cameras,
            up_axis=str(UsdGeom.GetStageUpAxis(self.stage)),
            meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(self.stage)),
            time=self.time,
            warnings=self.warnings,
            render_settings=rs,
            render_settings_source=self.render_settings_source,
            purposes=tuple(self.purposes),
            instances=inst.instances() if inst is not None and inst.count else None,
        )
        return scene

    # -- lights' shadow controls ------------------------------------------------------
    def read_shadow_controls(self, prim, light: Light, casters: list[str]) -> Light:
        """The UsdLux controls that change who casts ``light``'s shadow and how it is shaded, onto
        the light: ``collection:shadowLink`` (membership as ``Usd.CollectionAPI`` computes it;
        unauthored, USD's ``includeRoot = true`` includes everything) as the prims it leaves out,
        ``inputs:shadow:distance``, ``inputs:shadow:color``, ``inputs:shadow:falloff`` and
        ``falloffGamma``. A mesh placed by a PointInstancer casts when both the instancer and the
        prototype mesh are members. Falloff is read but not applied: a warning when authored."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        link = UsdLux.LightAPI(prim).GetShadowLinkCollectionAPI()
        excluded = []
        if link:
            query = link.ComputeMembershipQuery()
            for i, c in enumerate(casters):
                paths = {c.split("@")[0], c.split("@")[-1].split("[")[0]}  # the mesh, and its instancer if any
                if not all(query.IsPathIncluded(Sdf.Path(q)) for q in paths):
                    excluded.append(i)
        shadow = UsdLux.ShadowAPI(prim)
        dist = self.get(shadow.GetShadowDistanceAttr(), -1.0)
        dist = float(dist)
        if math.isnan(dist):
            raise self.err(prim, "inputs:shadow:distance = nan is not a number")
        if dist < 0.0 or math.isinf(dist):
            dist = -1.0  # USD: -1 (any negative value, or an infinite one) is no limit
        color = tuple(float(c) for c in self.get(shadow.GetShadowColorAttr(), (0.0, 0.0, 0.0)))
        if not all(math.isfinite(c) for c in color):
            raise self.err(prim, f"inputs:shadow:color = {color} is not finite")
        falloff = self.finite(prim, "inputs:shadow:falloff", self.get(shadow.GetShadowFalloffAttr(), -1.0))
        gamma = self.finite(prim, "inputs:shadow:falloffGamma", self.get(shadow.GetShadowFalloffGammaAttr(), 1.0))
        if falloff > 0.0:
            self.warn(prim, f"inputs:shadow:falloff = {falloff:g} (falloffGamma {gamma:g}) is not applied: the shadow ends "
                            "sharply at inputs:shadow:distance (UsdLux gives no formula for the fade)")
        light.shadow_excluded = tuple(excluded)
        light.shadow_distance = dist
        light.shadow_color = color
        light.shadow_falloff = falloff
        light.shadow_falloff_gamma = gamma
        return light

    # -- point instancers ----------------------------------------------------------
    def instancer_parts(self, prim):
        """What a ``UsdGeom.PointInstancer`` places, checked: (protoIndices [N] int64, USD's instance
        transforms (``ComputeInstanceTransformsAtTime``: positions, orientations, scales, the
        prototypes' own transforms; row-vector matrices), shown [N] bool (the mask of
        ``invisibleIds`` and inactive ids), the instancer's world matrix, moving (its instances move
        over time), {prototype index: (root prim, its meshes)}); None when it places nothing."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        pi = UsdGeom.PointInstancer(prim)
        protos = pi.GetPrototypesRel().GetForwardedTargets()
        indices = self.get(pi.GetProtoIndicesAttr())
        if indices is None or len(indices) == 0:
            return None
        indices = np.asarray(indices, np.int64)
        if not protos:
            raise self.err(prim, f"PointInstancer has {len(indices)} instances but no prototypes")
        if indices.min() < 0 or indices.max() >= len(protos):
            bad = int(np.argmax((indices < 0) | (indices >= len(protos))))
            raise self.err(prim, f"protoIndices[{bad}] = {int(indices[bad])} is out of range for {len(protos)} prototypes")
        xforms = pi.ComputeInstanceTransformsAtTime(self.timecode, self.timecode, UsdGeom.PointInstancer.IncludeProtoXform,
                                                    UsdGeom.PointInstancer.IgnoreMask)
        if xforms is None or len(xforms) != len(indices):
            raise self.err(prim, f"PointInstancer's positions/orientations/scales do not match its {len(indices)} protoIndices")
        mask = pi.ComputeMaskAtTime(self.timecode)  # empty: every instance shows
        keep = np.ones(len(indices), bool) if mask is None or len(mask) == 0 else np.asarray(mask, bool)
        M_pi = self.world(prim)
        # dynamic when the instancer moves its instances over time (or is moved)
        attrs = (pi.GetPositionsAttr(), pi.GetOrientationsAttr(), pi.GetScalesAttr(), pi.GetProtoIndicesAttr(), pi.GetInvisibleIdsAttr())
        moving = any(a and a.GetNumTimeSamples() > 1 for a in attrs) or self.is_dynamic(prim, None)
        meshes_of = {}
        for j, path in enumerate(protos):
            root = self.stage.GetPrimAtPath(path)
            if not root:
                raise self.err(prim, f"prototype {path} does not exist")
            found = []
            sub = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
            for q in sub:
                if q.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(q).ComputeVisibility(self.timecode) == UsdGeom.Tokens.invisible:
                    sub.PruneChildren()
                    continue
                if q.IsA(UsdGeom.PointInstancer):
                    self.warn(q, "a PointInstancer inside a prototype is not expanded; ignored")
                    sub.PruneChildren()
                elif q.IsA(UsdGeom.Mesh):
                    found.append(q)
                elif q.IsA(UsdGeom.Gprim):
                    self.warn(q, f"{q.GetTypeName()} is not a Mesh; ignored (convert it to a mesh to cast shadows)")
            meshes_of[j] = (root, found)
        return indices, xforms, keep, M_pi, moving, meshes_of

    def read_instancer(self, prim):
        """The meshes a ``UsdGeom.PointInstancer`` places, one copy per instance (flattened): the
        instance transforms from USD's own ``ComputeInstanceTransformsAtTime`` (positions,
        orientations, scales, the prototypes' own transforms) with the mask of ``invisibleIds``
        and inactive ids applied to them and to ``protoIndices``, each prototype's meshes read
        once per instance. Yields (mesh, name) with name ``mesh@instancer[i]``."""
        parts = self.instancer_parts(prim)
        if parts is None:
            return
        indices, xforms, keep, M_pi, moving, meshes_of = parts
        for i in np.nonzero(keep)[0]:
            root, found = meshes_of[int(indices[i])]
            # the instance transform maps the prototype root's own frame (its xform included) into the
            # instancer's; the meshes below the root keep their transforms relative to it
            self.world_override = (root, M_pi @ np.array(xforms[int(i)], dtype=np.float64).T)
            try:
                for q in found:
                    mesh = self.read_mesh(q)
                    if mesh is not None:
                        if moving:
                            mesh = (*mesh[:6], True, *mesh[7:])
                        yield mesh, f"{q.GetPath()}@{prim.GetPath()}[{int(i)}]"
            finally:
                self.world_override = None

    def read_instancer_instances(self, prim, inst: "_InstanceBuilder") -> None:
        """A ``UsdGeom.PointInstancer`` kept instanced (``instancing``): the checks of
        :meth:`instancer_parts`, each prototype a placed instance uses read once in its root's frame
        (shared by every instancer that names the same root), one instance per shown id with
        world(instancer) @ USD's instance transform, dynamic when the instancer moves its instances."""
        parts = self.instancer_parts(prim)
        if parts is None:
            return
        indices, xforms, keep, M_pi, moving, meshes_of = parts
        shown = np.flatnonzero(keep)
        if not len(shown):
            return
        protos = np.full(len(meshes_of), -1, np.int64)
        for j in np.unique(indices[shown]):
            root, found = meshes_of[int(j)]
            key = ("PointInstancer", str(root.GetPath()))
            if key not in inst.proto_of:
                self.world_override = (root, np.eye(4))  # the root's own frame
                try:
                    meshes = [(m, str(q.GetPath())) for q in found for m in [self.read_mesh(q)] if m is not None]
                finally:
                    self.world_override = None
                inst.add_prototype(key, str(root.GetPath()), str(root.GetPath()), meshes)
            protos[j] = inst.proto_of[key]
        X = np.array([np.array(xforms[int(i)], dtype=np.float64).T for i in shown]).reshape(-1, 4, 4)
        W = M_pi @ X
        placed = protos[indices[shown]] >= 0  # a prototype without triangles places nothing
        if placed.any():
            where = inst.add_prim(str(prim.GetPath()))
            inst.add(protos[indices[shown]][placed], W[placed], where, shown[placed], moving)

    # -- instanceable prims --------------------------------------------------------
    def read_instance(self, prim, inst: "_InstanceBuilder") -> bool:
        """An instanceable prim kept instanced (``instancing``): its USD prototype's meshes, read once
        through the proxies of the first instance that resolves them alike (material bindings and
        purposes resolve on the proxies, and may come from above the instance), in the instance
        prim's frame; nested instances inside are flattened into it. False (read it as when flat)
        for an invisible prim, one that is itself a mesh, light, camera or PointInstancer, or one
        whose prototype holds a light, a camera or a PointInstancer."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        if prim.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(prim).ComputeVisibility(self.timecode) == UsdGeom.Tokens.invisible:
            return False
        if prim.IsA(UsdGeom.Gprim) or _placed_apart(prim, UsdGeom, UsdLux):
            return False
        ppath = str(prim.GetPrototype().GetPath())
        ipath = prim.GetPath()
        if ppath not in inst.scan:
            meshes, others, mixed = [], [], False
            sub = iter(Usd.PrimRange(prim, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
            next(sub)  # the instance prim itself
            for q in sub:
                if q.IsA(UsdGeom.Imageable) and UsdGeom.Imageable(q).ComputeVisibility(self.timecode) == UsdGeom.Tokens.invisible:
                    sub.PruneChildren()
                    continue
                if _placed_apart(q, UsdGeom, UsdLux):
                    mixed = True
                    break
                if q.IsA(UsdGeom.Mesh):
                    meshes.append(q.GetPath().MakeRelativePath(ipath))
                elif q.IsA(UsdGeom.Gprim):
                    others.append(q.GetPath().MakeRelativePath(ipath))
            inst.scan[ppath] = None if mixed else (meshes, others)
        scan = inst.scan[ppath]
        if scan is None:
            return False
        meshes, others = scan
        # how this instance resolves its prototype's meshes: purpose included, materials bound
        resolved, proxies = [], []
        for rel in meshes:
            q = self.stage.GetPrimAtPath(ipath.AppendPath(rel))
            if UsdGeom.Imageable(q).ComputePurpose() not in self.purposes:
                resolved.append(None)
                continue
            subsets = UsdShade.MaterialBindingAPI(q).GetMaterialBindSubsets()
            resolved.append((self.material_key(q, ipath), *(self.material_key(g.GetPrim(), ipath) for g in subsets)))
            proxies.append(q)
        key = (ppath, tuple(resolved))
        if key not in inst.proto_of:
            for rel in others:
                q = self.stage.GetPrimAtPath(ipath.AppendPath(rel))
                if UsdGeom.Imageable(q).ComputePurpose() in self.purposes:
                    self.warn(q, f"{q.GetTypeName()} is not a Mesh; ignored (convert it to a mesh to cast shadows)")
            self.world_override, self.dynamic_stop = (prim, np.eye(4)), prim  # the instance prim's frame
            try:
                read = [(m, str(q.GetPath())) for q in proxies for m in [self.read_mesh(q)] if m is not None]
            finally:
                self.world_override, self.dynamic_stop = None, None
            inst.add_prototype(key, ppath, str(ipath), read)
        j = inst.proto_of[key]
        if j < 0:
            return True  # nothing of it to draw
        M = self.world(prim)
        if not np.all(np.isfinite(M)):
            raise self.err(prim, "world transform is not finite (NaN or inf in its xformOps or an ancestor's)")
        inst.add(np.array([j]), M[None], inst.add_prim(str(ipath)), np.array([-1]), self.is_dynamic(prim, None))
        return True

    def material_key(self, prim, ipath):
        """How an instance proxy's material binding tells prototypes apart: a material inside the
        instance by its path relative to the instance prim (every instance has its own proxy of it,
        the same material), any other by its index in the scene's materials."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if material and material.GetPath().HasPrefix(ipath):
            return str(material.GetPath().MakeRelativePath(ipath))
        return self.material_for(prim)

    def light_linking_instances(self, shadow_lights, inst: "_InstanceBuilder") -> str | None:
        """The first shadow-casting light whose ``collection:shadowLink`` leaves out a caster of the
        flat load (a soup prim, an instanced mesh as the flat loader names it), or None."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        paths = None
        for lp, light in shadow_lights:
            if light.shadow_excluded:
                return str(lp.GetPath())
            link = UsdLux.LightAPI(lp).GetShadowLinkCollectionAPI()
            if not link:
                continue
            query = link.ComputeMembershipQuery()
            paths = inst.flat_paths() if paths is None else paths
            if not all(query.IsPathIncluded(Sdf.Path(q)) for group in paths for q in group):
                return str(lp.GetPath())
        return None

    # -- meshes ------------------------------------------------------------------
    def read_mesh(self, prim):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        mesh = UsdGeom.Mesh(prim)
        points = self.get(mesh.GetPointsAttr())
        counts = self.get(mesh.GetFaceVertexCountsAttr())
        indices = self.get(mesh.GetFaceVertexIndicesAttr())
        if points is None or counts is None or indices is None or len(points) == 0 or len(counts) == 0:
            self.warn(prim, "mesh has no points or faces; ignored")
            return None
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        counts = np.asarray(counts, dtype=np.int64)
        idx = np.asarray(indices, dtype=np.int64)
        if not np.all(np.isfinite(p)):
            bad = int(np.argwhere(~np.isfinite(p).all(axis=1))[0, 0])
            raise self.err(prim, f"points[{bad}] is not finite (NaN or inf)")
        if np.any(counts < 0):
            bad = int(np.argmax(counts < 0))
            raise self.err(prim, f"faceVertexCounts[{bad}] = {int(counts[bad])} is negative")
        if counts.sum() != len(idx):
            raise self.err(prim, f"faceVertexCounts sum to {int(counts.sum())} but faceVertexIndices has {len(idx)} entries")
        if len(idx) and (idx.min() < 0 or idx.max() >= len(p)):
            bad = int(np.argmax((idx < 0) | (idx >= len(p))))
            raise self.err(prim, f"faceVertexIndices[{bad}] = {int(idx[bad])} is out of range for {len(p)} points")
        if np.any(counts < 3):
            self.warn(prim, f"{int(np.sum(counts < 3))} faces with fewer than 3 vertices ignored")

        # fan triangulation: face f with n vertices -> (v0, vi, vi+1), i = 1..n-2
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        ntri_face = np.maximum(counts - 2, 0)
        face_of_tri = np.repeat(np.arange(len(counts)), ntri_face)
        k = np.arange(ntri_face.sum()) - np.repeat(np.cumsum(ntri_face) - ntri_face, ntri_face)
        c0 = starts[face_of_tri]
        corners = np.stack([c0, c0 + k + 1, c0 + k + 2], axis=1)  # face-vertex (corner) indices
        orient = self.get(mesh.GetOrientationAttr(), UsdGeom.Tokens.rightHanded)
        if orient == UsdGeom.Tokens.leftHanded:
            corners = corners[:, [0, 2, 1]]
        tris = idx[corners]

        # world transform
        M = self.world(prim)
        if not np.all(np.isfinite(M)):
            raise self.err(prim, "world transform is not finite (NaN or inf in its xformOps or an ancestor's)")
        with np.errstate(over="ignore", invalid="ignore"):
            pw = p @ M[:3, :3].T + M[:3, 3]
        pw32 = pw.astype(np.float32)  # what the kernels see
        if not np.all(np.isfinite(pw32)):
            bad = int(np.argwhere(~np.isfinite(pw32).all(axis=1))[0, 0])
            raise self.err(prim, f"points[{bad}] is not finite in float32 once transformed to world space ({p[bad].tolist()})")
        if np.linalg.det(M[:3, :3]) < 0:  # mirroring transform flips the winding
            corners = corners[:, [0, 2, 1]]
            tris = tris[:, [0, 2, 1]]

        # zero-area triangles (repeated or collinear corners in float32) cannot block a ray: dropped
        q = pw32.astype(np.float64)[tris]
        area2 = np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
        keep = area2 > 0.0
        if not keep.all():
            self.warn(prim, f"{int((~keep).sum())} zero-area triangles ignored")
            if not keep.any():
                return None
            tris, corners, face_of_tri = tris[keep], corners[keep], face_of_tri[keep]
        uv = self.read_st(prim, mesh, corners, face_of_tri, tris)
        mat = self.bind_materials(prim, mesh, len(counts), face_of_tri)
        ds = bool(self.get(mesh.GetDoubleSidedAttr(), False))  # UsdGeom's uniform doubleSided (the eye view's back-face culling)
        stray = prim.GetAttribute("primvars:doubleSided")
        if stray and stray.HasAuthoredValue():
            self.warn(prim, "primvars:doubleSided is not a UsdGeom property; ignored (the mesh's doubleSided attribute "
                            f"is read: {str(ds).lower()})")
        baked = self.read_primvar(prim, corners, face_of_tri, tris, "wsoft:bakedLight", 3)
        return pw, tris.astype(np.int32), mat, uv, ds, closed_orientation(pw, tris), self.is_dynamic(prim, mesh), baked, face_of_tri

    def is_dynamic(self, prim, mesh) -> bool:
        """A *dynamic caster* (Salzman's sense): time-sampled points, a time-varying transform on the
        prim or an ancestor, or ``wsoft:dynamic = true`` on the prim or an ancestor."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        if mesh is not None and mesh.GetPointsAttr().GetNumTimeSamples() > 1:
            return True
        p = prim
        while p and not p.IsPseudoRoot() and p != self.dynamic_stop:
            key = str(p.GetPath())
            if key not in self.dynamic_cache:
                attr = p.GetAttribute("wsoft:dynamic")
                flag = bool(attr and attr.HasAuthoredValue() and attr.Get(self.timecode))
                if not flag and p.IsA(UsdGeom.Xformable):
                    flag = UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                self.dynamic_cache[key] = flag
            if self.dynamic_cache[key]:
                return True
            p = p.GetParent()
        return False

    def read_st(self, prim, mesh, corners, face_of_tri, tris, name: str = "st"):
        out = self.read_primvar(prim, corners, face_of_tri, tris, name, 2)
        return np.zeros((len(tris), 3, 2), np.float32) if out is None else out

    def read_primvar(self, prim, corners, face_of_tri, tris, name: str, width: int):
        """A primvar's values at each triangle corner, shape [T, 3, width]; None when absent."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        if not pv or not pv.HasValue():
            return None
        vals = pv.ComputeFlattened(self.timecode)
        if vals is None or len(vals) == 0:
            return None
        v = np.asarray(vals, dtype=np.float32).reshape(-1, width)
        interp = pv.GetInterpolation()
        try:
            if interp == UsdGeom.Tokens.faceVarying:
                out = v[corners]
            elif interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
                out = v[tris]
            elif interp == UsdGeom.Tokens.uniform:
                out = np.repeat(v[face_of_tri][:, None, :], 3, axis=1)
            else:  # constant
                out = np.broadcast_to(v[0], (len(tris), 3, width)).copy()
        except IndexError:
            raise self.err(prim, f"primvars:{name} has {len(v)} values, too few for {interp} interpolation") from None
        return out.astype(np.float32)

    def bind_materials(self, prim, mesh, nfaces: int, face_of_tri):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        face_mat = np.full(nfaces, self.material_for(prim), np.int32)
        subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
        for subset in subsets:
            ind = self.get(subset.GetIndicesAttr())
            if ind is None:
                continue
            ind = np.asarray(ind, dtype=np.int64)
            if len(ind) and (ind.min() < 0 or ind.max() >= nfaces):
                raise self.err(subset.GetPrim(), f"GeomSubset face index out of range for {nfaces} faces")
            face_mat[ind] = self.material_for(subset.GetPrim())
        return face_mat[face_of_tri]

    def material_for(self, prim) -> int:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if not material:
            color = self.display_color(prim)
            if color is None:
                return 0
            key = f"(displayColor){color}"
            if key not in self.material_index:
                self.material_index[key] = len(self.materials)
                self.materials.append(Material(path=key, albedo=color))
            return self.material_index[key]
        mpath = str(material.GetPath())
        if mpath not in self.material_index:
            self.material_index[mpath] = len(self.materials)
            self.materials.append(self.read_material(material))
        return self.material_index[mpath]

    def display_color(self, prim):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        if not prim.IsA(UsdGeom.Gprim):
            return None
        pv = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        if pv and pv.HasValue():
            v = pv.ComputeFlattened(self.timecode)
            if v is not None and len(v):
                c = np.asarray(v, dtype=np.float64).reshape(-1, 3).mean(axis=0)
                return tuple(float(x) for x in np.clip(c, 0, 1))
        return None

    def read_material(self, material) -> Material:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        mat = Material(path=str(material.GetPath()))
        shader = material.ComputeSurfaceSource()[0]
        if not shader:
            return mat
        sid = shader.GetIdAttr().Get() if shader.GetIdAttr() else None
        if sid != "UsdPreviewSurface":
            self.warn(material.GetPrim(), f"surface shader {sid!r} is not UsdPreviewSurface; treated as opaque grey")
            return mat
        diffuse = shader.GetInput("diffuseColor")
        if diffuse and not diffuse.HasConnectedSource():
            v = diffuse.Get(self.timecode)
            if v is not None:
                mat.albedo = tuple(float(x) for x in v)
        thr = shader.GetInput("opacityThreshold")
        mat.opacity_threshold = float(thr.Get(self.timecode) or 0.0) if thr else 0.0
        op = shader.GetInput("opacity")
        if not op:
            return mat
        if op.HasConnectedSource():
            src, out_name, _ = op.GetConnectedSource()
            tex_shader = UsdShade.Shader(src.GetPrim())
            tid = tex_shader.GetIdAttr().Get() if tex_shader and tex_shader.GetIdAttr() else None
            if tid != "UsdUVTexture":
                self.warn(material.GetPrim(), f"opacity is connected to {tid!r}, not a UsdUVTexture; treated as opaque")
                return mat
            if mat.opacity_threshold <= 0.0:
                self.warn(material.GetPrim(), "textured opacity without opacityThreshold (translucency) is not modelled; opaque")
                return mat
            mat.texture = self.read_texture(tex_shader, str(out_name), material.GetPrim())
        else:
            v = op.Get(self.timecode)
            mat.opacity = float(v) if v is not None else 1.0
            if mat.opacity < 1.0 and mat.opacity_threshold <= 0.0:
                self.warn(material.GetPrim(), f"constant opacity {mat.opacity:g} (translucency): opaque for every technique but salzman (its transparency component)")
        return mat

    def read_texture(self, tex_shader, channel: str, mat_prim) -> int:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        file_in = tex_shader.GetInput("file")
        asset = file_in.Get(self.timecode) if file_in else None
        if asset is None:
            self.warn(tex_shader.GetPrim(), "UsdUVTexture has no file; surface is opaque")
            return -1
        resolved = asset.resolvedPath or ""
        wraps = []
        for nm in ("wrapS", "wrapT"):
            w = tex_shader.GetInput(nm)
            wv = str(w.Get(self.timecode)) if w and w.Get(self.timecode) is not None else "useMetadata"
            wraps.append(WRAP_NAMES.get(wv, 0))
        key = (resolved or asset.path, channel, tuple(wraps))
        if key in self.texture_index:
            return self.texture_index[key]
        data = _read_asset(resolved) if resolved else None  # through USD's asset resolver: files inside a .usdz too
        if data is None:
            self.warn(tex_shader.GetPrim(), f"texture {asset.path!r} not found; surface is opaque")
            return -1
        try:
            import io

            from PIL import Image

            with Image.open(io.BytesIO(data)) as im:
                im.load()  # a truncated file fails here, not later
                rgba = _rgba01(im)
        except Exception as exc:
            self.warn(tex_shader.GetPrim(), f"texture {asset.path!r} cannot be read ({' '.join(str(exc).split())}); surface is opaque")
            return -1
        ch = {"r": 0, "g": 1, "b": 2, "a": 3}.get(channel, 3)
        data = np.ascontiguousarray(rgba[::-1, :, ch])  # bottom-up rows: st (0,0) = lower-left
        self.textures.append(Texture(asset=asset.path, data=data, wrap_s=wraps[0], wrap_t=wraps[1]))
        self.texture_index[key] = len(self.textures) - 1
        return len(self.textures) - 1

    # -- lights ------------------------------------------------------------------
    def read_light(self, prim, type_name: str) -> Light | None:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        M = self.world(prim)
        axes = M[:3, :3]
        scale = np.linalg.norm(axes, axis=0)
        if np.any(scale < 1e-12) or not np.all(np.isfinite(M)):
            raise self.err(prim, "light transform is singular or not finite")
        frame = axes / scale
        # re-orthonormalise (shear would make the frame skew)
        u, _, vt = np.linalg.svd(frame)
        frame = u @ vt
        pos = M[:3, 3].copy()
        lux = UsdLux.LightAPI(prim)
        intensity = self.finite(prim, "inputs:intensity", self.get(lux.GetIntensityAttr(), 1.0))
        exposure = self.finite(prim, "inputs:exposure", self.get(lux.GetExposureAttr(), 0.0))
        if not -126.0 <= exposure <= 127.0:
            raise self.err(prim, f"inputs:exposure = {exposure:g} is out of range (2^exposure must be a finite float: -126..127)")
        intensity *= 2.0 ** exposure
        color = tuple(float(c) for c in self.get(lux.GetColorAttr(), (1.0, 1.0, 1.0)))
        common = dict(path=str(prim.GetPath()), position=pos, frame=frame, intensity=intensity, color=color)
        if type_name == "RectLight":
            lt = UsdLux.RectLight(prim)
            w = self.size(prim, "inputs:width", self.get(lt.GetWidthAttr(), 1.0)) * scale[0]
            h = self.size(prim, "inputs:height", self.get(lt.GetHeightAttr(), 1.0)) * scale[1]
            if w == 0 and h == 0:
                self.warn(prim, "RectLight has zero width and height: rendered as a point light (hard shadows)")
                return Light(kind=LIGHT_POINT, **common)
            if w == 0 or h == 0:
                self.warn(prim, f"RectLight has zero {'width' if w == 0 else 'height'}: it emits from a line segment (no area)")
            return Light(kind=LIGHT_RECT, half_size=(0.5 * w, 0.5 * h), **common)
        if type_name == "DiskLight":
            r = self.size(prim, "inputs:radius", self.get(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5)) * 0.5 * (scale[0] + scale[1])
            if r == 0:
                self.warn(prim, "DiskLight has radius 0: rendered as a point light (hard shadows)")
            return Light(kind=LIGHT_DISK if r > 0 else LIGHT_POINT, radius=max(r, 0.0), **common)
        if type_name == "SphereLight":
            lt = UsdLux.SphereLight(prim)
            r = self.size(prim, "inputs:radius", self.get(lt.GetRadiusAttr(), 0.5)) * float(np.mean(scale))
            if bool(self.get(lt.GetTreatAsPointAttr(), False)) or r <= 0:
                return Light(kind=LIGHT_POINT, **common)
            return Light(kind=LIGHT_SPHERE, radius=r, **common)
        angle = self.finite(prim, "inputs:angle", self.get(UsdLux.DistantLight(prim).GetAngleAttr(), 0.53))
        if not (0.0 <= angle < 180.0):
            raise self.err(prim, f"DistantLight angle {angle} must be in [0, 180) degrees")
        return Light(kind=LIGHT_DISTANT, angle_deg=angle, **common)

    # -- cameras -----------------------------------------------------------------
    def read_camera(self, prim) -> Camera:
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = _pxr()
        cam = UsdGeom.Camera(prim).GetCamera(self.timecode)
        M = np.array(cam.transform, dtype=np.float64).T
        axes = M[:3, :3]
        scale = np.linalg.norm(axes, axis=0)
        if np.any(scale < 1e-12) or not np.all(np.isfinite(M)):
            raise self.err(prim, "camera transform is singular or not finite")
        M[:3, :3] = axes / scale
        clip = (float(cam.clippingRange.min), float(cam.clippingRange.max))
        if not all(math.isfinite(c) for c in clip) or not 0.0 <= clip[0] < clip[1]:
            self.warn(prim, f"clippingRange {clip} is empty or inverted (need 0 <= near < far): this camera sees nothing")
        ortho = cam.projection == Gf.Camera.Orthographic
        ha, va = float(cam.horizontalAperture), float(cam.verticalAperture)
        ho, vo = float(cam.horizontalApertureOffset), float(cam.verticalApertureOffset)
        if ha <= 0 or va <= 0:
            raise self.err(prim, "camera apertures must be > 0")
        if ortho:
            # apertures are in tenths of a scene unit
            tan_half = (0.05 * ha, 0.05 * va)
            offset = (0.1 * ho, 0.1 * vo)
        else:
            f = float(cam.focalLength)
            if f <= 0:
                raise self.err(prim, "camera focalLength must be > 0")
            tan_half = (0.5 * ha / f, 0.5 * va / f)
            offset = (ho / f, vo / f)
        return Camera(path=str(prim.GetPath()), to_world=M, orthographic=ortho, tan_half=tan_half, offset=offset, clip=clip)


def _placed_apart(prim, UsdGeom, UsdLux) -> bool:
    """Is ``prim`` something an instanceable prim's prototype cannot keep instanced: a light, a
    camera or a PointInstancer?"""
    type_name = prim.GetTypeName()
    return (prim.IsA(UsdGeom.Camera) or prim.IsA(UsdGeom.PointInstancer) or prim.HasAPI(UsdLux.LightAPI)
            or type_name in _HANDLED_LIGHTS or type_name.endswith("Light"))


class _InstanceBuilder:
    """The instances a load keeps (``load_scene(..., instancing=True)``) as the reader finds them:
    prototypes by key, and per instance its prototype, transform, prim, id and dynamic flag. Shares
    the reader's ``prims`` and ``prim_points`` lists (prototype meshes and instance prims get empty
    ``prim_points`` rows: their points are not in the soup)."""

    def __init__(self, prims: list[str], prim_points: list):
        self.prims, self.prim_points = prims, prim_points
        self.prim_index: dict[str, int] = {}
        self.prototypes: list[Prototype] = []
        self.proto_of: dict[tuple, int] = {}  # key -> index into prototypes (-1: no triangles)
        self.scan: dict[str, tuple | None] = {}  # USD prototype path -> (mesh paths, other gprims) relative to the instance, None: read flat
        self.proto, self.xform, self.prim, self.ids, self.dynamic = [], [], [], [], []

    @property
    def count(self) -> int:
        return sum(len(p) for p in self.proto)

    def add_prim(self, name: str) -> int:
        if name not in self.prim_index:
            self.prims.append(name)
            self.prim_points.append((0, 0))
            self.prim_index[name] = len(self.prims) - 1
        return self.prim_index[name]

    def add_prototype(self, key, path: str, root: str, meshes: list) -> None:
        """Prototype ``key`` from the meshes read (``read_mesh`` tuples and their names), -1 when none."""
        if not meshes:
            self.proto_of[key] = -1
            return
        pts, tris, cols, prim_points, baked = [], [], {k: [] for k in ("prim", "mat", "uv", "ds", "cl", "dyn", "face")}, [], []
        n = 0
        for (p, t, m, uv, ds, closed, dynamic, bk, faces), name in meshes:
            j = self.add_prim(name)
            prim_points.append((j, n, len(p)))
            pts.append(p)
            tris.append(t + n)
            n += len(p)
            cols["prim"].append(np.full(len(t), j, np.int32))
            cols["mat"].append(m)
            cols["uv"].append(uv)
            cols["ds"].append(np.full(len(t), ds, bool))
            cols["cl"].append(np.full(len(t), closed, np.int8))
            cols["dyn"].append(np.full(len(t), dynamic, bool))
            cols["face"].append(faces.astype(np.int32))
            baked.append((bk, len(t)))
        dyn = np.concatenate(cols["dyn"])
        self.proto_of[key] = len(self.prototypes)
        self.prototypes.append(Prototype(
            path=path, points=np.concatenate(pts).astype(np.float32), triangles=np.concatenate(tris).astype(np.int32),
            tri_prim=np.concatenate(cols["prim"]), tri_material=np.concatenate(cols["mat"]).astype(np.int32),
            tri_uv=np.concatenate(cols["uv"]).astype(np.float32), tri_double_sided=np.concatenate(cols["ds"]),
            tri_closed=np.concatenate(cols["cl"]), tri_face=np.concatenate(cols["face"]),
            tri_dynamic=dyn if dyn.any() else None, tri_baked=_baked(baked), root=root,
            prim_points=np.asarray(prim_points, np.int64).reshape(-1, 3),
        ))

    def add(self, proto: np.ndarray, xform: np.ndarray, prim: int, ids: np.ndarray, dynamic: bool) -> None:
        self.proto.append(np.asarray(proto, np.int32))
        self.xform.append(np.asarray(xform, np.float64).reshape(-1, 4, 4))
        self.prim.append(np.full(len(proto), prim, np.int32))
        self.ids.append(np.asarray(ids, np.int32))
        self.dynamic.append(np.full(len(proto), bool(dynamic), bool))

    def instances(self) -> Instances:
        return Instances(prototypes=self.prototypes, proto=np.concatenate(self.proto), xform=np.concatenate(self.xform),
                         prim=np.concatenate(self.prim), instance_id=np.concatenate(self.ids), dynamic=np.concatenate(self.dynamic))

    def flat_paths(self) -> set[tuple[str, ...]]:
        """The prim paths a flat load's instanced meshes answer to in a shadowLink test: (the
        prototype mesh, the PointInstancer) for an instancer's, (the instance proxy) for an
        instanceable prim's."""
        out = set()
        for proto_k, prim_k, ids_k in zip(self.proto, self.prim, self.ids):
            for pj, where, iid in {(int(a), int(b), int(c) >= 0) for a, b, c in zip(proto_k, prim_k, ids_k)}:
                proto = self.prototypes[pj]
                for m in np.unique(proto.tri_prim):
                    name = self.prims[int(m)]
                    if iid:
                        out.add((name, self.prims[where]))
                    else:
                        out.add((self.prims[where] + name[len(proto.root):],))
        return out


def _read_asset(resolved: str) -> bytes | None:
    """The bytes of a resolved asset path (a file, or a file inside a package such as
    ``scene.usdz[textures/a.png]``), read through USD's asset resolver; None when absent."""
    from pxr import Ar

    try:
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    except Exception:
        return None
    if asset is None:
        return None
    buf = asset.GetBuffer()
    return None if buf is None else bytes(buf)


def _rgba01(im) -> np.ndarray:
    """An image's RGBA in [0, 1], whatever its bit depth (8- and 16-bit, palette, grey, float)."""
    if im.mode in ("I;16", "I;16B", "I;16L", "I"):
        a = np.asarray(im, dtype=np.float64)
        top = 65535.0 if im.mode.startswith("I;16") or a.max(initial=0) > 255 else 255.0
        g = np.clip(a / top, 0.0, 1.0).astype(np.float32)
        return np.stack([g, g, g, np.ones_like(g)], axis=-1)
    if im.mode == "F":
        g = np.clip(np.asarray(im, dtype=np.float32), 0.0, 1.0)
        return np.stack([g, g, g, np.ones_like(g)], axis=-1)
    return np.asarray(im.convert("RGBA"), dtype=np.float32) / 255.0


def _baked(parts: list[tuple[np.ndarray | None, int]]) -> np.ndarray | None:
    """Per-corner baked light [T, 3, 3] (NaN where a mesh has none), or None if no mesh has any."""
    if all(b is None for b, _ in parts):
        return None
    return np.concatenate([np.full((n, 3, 3), np.nan, np.float32) if b is None else b.astype(np.float32) for b, n in parts])


def closed_orientation(points: np.ndarray, tris: np.ndarray) -> int:
    """+1 if the triangles form a closed, consistently wound surface facing outward, -1 if it
    faces inward, 0 if it is open, non-manifold or inconsistently wound.

    Closed: every directed edge (a, b) appears once and its reverse (b, a) appears once. For
    such a surface the nearest hit along any ray from outside is a face turned toward the ray,
    which lets the light-view rasterizer skip the faces turned away (exactly).
    """
    if len(tris) < 4:
        return 0
    n = int(points.shape[0])
    a = tris.astype(np.int64)
    fwd = np.concatenate([a[:, 0] * n + a[:, 1], a[:, 1] * n + a[:, 2], a[:, 2] * n + a[:, 0]])
    rev = np.concatenate([a[:, 1] * n + a[:, 0], a[:, 2] * n + a[:, 1], a[:, 0] * n + a[:, 2]])
    fwd.sort()
    if np.any(fwd[1:] == fwd[:-1]):
        return 0
    rev.sort()
    if not np.array_equal(fwd, rev):
        return 0
    p = points[a].astype(np.float64)
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    scale = float(np.ptp(points, axis=0).max()) ** 3 if len(points) else 0.0
    if abs(vol) <= 1e-9 * max(scale, 1e-30):
        return 0
    return 1 if vol > 0 else -1


def auto_camera(scene: Scene, aspect: float = 4.0 / 3.0) -> Camera:
    """A perspective camera looking down at the scene from above and to the side (up-axis aware),
    placed at the smallest distance at which all 8 corners of the scene's bounds are in view."""
    lo, hi = scene.bounds
    center = 0.5 * (lo + hi)
    up = np.array([0.0, 0.0, 1.0]) if scene.up_axis == "Z" else np.array([0.0, 1.0, 0.0])
    side = np.array([1.0, 0.0, 0.0])
    fwd_h = np.cross(up, side)  # a horizontal direction
    view_dir = -(0.55 * up + 0.6 * fwd_h + 0.35 * side)
    view_dir /= np.linalg.norm(view_dir)
    z = -view_dir
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    tan_x = math.tan(math.radians(27.0))
    tan_y = tan_x / aspect
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]) - center
    cx, cy, cz = corners @ x, corners @ y, corners @ z
    dist = float(np.max(np.maximum(cz + np.abs(cx) / tan_x, cz + np.abs(cy) / tan_y))) * 1.02
    dist = max(dist, 1e-3 * scene.diagonal)
    eye = center + z * dist
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, z, eye
    return Camera(path="(automatic)", to_world=M, tan_half=(tan_x, tan_y), clip=(dist * 1e-4, dist + 2 * scene.diagonal))
