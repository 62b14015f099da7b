"""Writing prims onto a USD stage: the stage itself, meshes, materials, lights, cameras, instances.

Every builder takes the stage first and returns the schema it defined. A stage is Z-up (or Y-up)
with ``metersPerUnit = 1`` and an Xform ``/World``; in memory for a test, or a new file for a
bundled stage. A mesh comes from a :data:`~wsoft.stages.mesh.MeshData` (:func:`add_mesh`) or is
one of the shapes :func:`add_quad` and :func:`add_box` build.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

from wsoft.stages.mesh import MeshData, box_mesh, quad_mesh

# --------------------------------------------------------------------------- stage


def make_stage(up: str = "Z", path: str | None = None) -> Usd.Stage:
    """A stage with ``metersPerUnit = 1``, its up axis (``"Z"`` or ``"Y"``) and a ``/World`` Xform.

    ``path``: a new file there (one already there is replaced) whose default prim is ``/World``;
    without it, a stage in memory.
    """
    if path is None:
        stage = Usd.Stage.CreateInMemory()
    else:
        if os.path.exists(path):
            os.remove(path)
        stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    world = UsdGeom.Xform.Define(stage, "/World")
    if path is not None:
        stage.SetDefaultPrim(world.GetPrim())
    return stage


# --------------------------------------------------------------------------- meshes


def add_mesh(stage: Usd.Stage, path: str, m: MeshData, double_sided: bool | None = None,
             material: UsdShade.Material | None = None, *, st=None, st_interpolation: str = "faceVarying",
             minimal: bool = False) -> UsdGeom.Mesh:
    """A mesh with the points (as float32), face counts and indices of ``m``.

    Unless ``minimal``, it also authors ``subdivisionScheme = none``, a right-handed orientation,
    ``doubleSided`` (false when not given) and its extent; ``minimal`` authors ``doubleSided`` only
    when given. ``material`` is bound; ``st``: texture coordinates, ``[K, 2]`` for
    ``st_interpolation`` (one per face corner for faceVarying, one per point for vertex).
    """
    pts, counts, idx = m
    mesh = UsdGeom.Mesh.Define(stage, path)
    p32 = np.ascontiguousarray(pts, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(p32))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.asarray(counts, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(idx, dtype=np.int32)))
    if not minimal:
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    if not minimal or double_sided is not None:
        mesh.CreateDoubleSidedAttr(bool(double_sided))
    if not minimal:
        lo, hi = p32.min(axis=0), p32.max(axis=0)
        mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    if material is not None:
        bind(mesh.GetPrim(), material)
    if st is not None:
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, st_interpolation)
        pv.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(st, dtype=np.float32)))
    return mesh


def add_quad(stage: Usd.Stage, path: str, center, half: float, *, normal_axis: str = "z", double_sided: bool = True,
             st: bool = False, dynamic: bool = False) -> UsdGeom.Mesh:
    """A square of half-side ``half`` in the plane perpendicular to ``normal_axis`` (z: the XY
    plane), counter-clockwise seen from +axis (a minimal mesh); ``st``: texture coordinates (0..1
    over it, one per point); ``dynamic``: marked ``wsoft:dynamic = true``."""
    cx, cy, cz = center
    if normal_axis == "z":
        pts = [(cx - half, cy - half, cz), (cx + half, cy - half, cz), (cx + half, cy + half, cz), (cx - half, cy + half, cz)]
    else:  # y
        pts = [(cx - half, cy, cz - half), (cx - half, cy, cz + half), (cx + half, cy, cz + half), (cx + half, cy, cz - half)]
    mesh = add_mesh(stage, path, quad_mesh(pts), double_sided, minimal=True,
                    st=[(0, 0), (1, 0), (1, 1), (0, 1)] if st else None, st_interpolation=UsdGeom.Tokens.vertex)
    if dynamic:
        set_custom_bool(mesh.GetPrim(), "wsoft:dynamic", True)
    return mesh


def add_box(stage: Usd.Stage, path: str, lo, hi) -> UsdGeom.Mesh:
    """A closed, outward-wound box between the corners ``lo`` and ``hi`` (a minimal mesh)."""
    return add_mesh(stage, path, box_mesh(lo, hi), minimal=True)


# --------------------------------------------------------------------------- materials


def add_material(stage: Usd.Stage, path: str, color: Sequence[float], roughness: float = 0.7) -> UsdShade.Material:
    """A UsdPreviewSurface material of diffuse ``color`` (metallic 0), under a Scope defined when missing."""
    _scope_above(stage, path)
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, path + "/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(roughness))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def add_cutout_material(stage: Usd.Stage, path: str, color: Sequence[float], texture: str, *, threshold: float = 0.5,
                        wrap: str = "repeat", rgb_output: bool = False) -> UsdShade.Material:
    """A cutout: a UsdPreviewSurface whose opacity is the alpha of the UsdUVTexture ``texture`` (st
    from the ``st`` primvar, ``wrap`` on both axes) with ``opacityThreshold``; under a Scope defined
    when missing. ``rgb_output``: the texture also declares its ``rgb`` output."""
    _scope_above(stage, path)
    mat = UsdShade.Material.Define(stage, path)
    surf = UsdShade.Shader.Define(stage, path + "/PreviewSurface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.7)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(float(threshold))
    reader = UsdShade.Shader.Define(stage, path + "/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    tex = UsdShade.Shader.Define(stage, path + "/AlphaTexture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture))
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    if rgb_output:
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(tex.ConnectableAPI(), "a")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def _scope_above(stage: Usd.Stage, path: str) -> None:
    looks = Sdf.Path(path).GetParentPath()
    if not stage.GetPrimAtPath(looks):
        UsdGeom.Scope.Define(stage, looks)


def bind(prim: Usd.Prim, mat: UsdShade.Material) -> None:
    """Bind ``mat`` to ``prim`` (the MaterialBindingAPI applied)."""
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)


# --------------------------------------------------------------------------- lights


def _place(xformable, at) -> None:
    """A translate op to the point ``at``, or a transform op of the Gf.Matrix4d ``at``."""
    if isinstance(at, Gf.Matrix4d):
        xformable.AddTransformOp().Set(at)
    else:
        xformable.AddTranslateOp().Set(Gf.Vec3d(*map(float, at)))


def add_rect_light(stage: Usd.Stage, path: str, pos, w: float, h: float, shadow: bool | None = None, *,
                   intensity: float | None = None) -> UsdLux.RectLight:
    """A RectLight of ``w x h`` emitting down its local −Z, placed at the point ``pos`` (or by the
    Gf.Matrix4d ``pos``); ``shadow``: author ``inputs:shadow:enable``."""
    light = UsdLux.RectLight.Define(stage, path)
    light.CreateWidthAttr(w)
    light.CreateHeightAttr(h)
    if intensity is not None:
        light.CreateIntensityAttr(float(intensity))
    _place(light, pos)
    if shadow is not None:
        UsdLux.ShadowAPI.Apply(light.GetPrim()).CreateShadowEnableAttr(shadow)
    return light


def add_sphere_light(stage: Usd.Stage, path: str, pos, radius: float, intensity: float | None = None) -> UsdLux.SphereLight:
    """A SphereLight of ``radius`` at ``pos``."""
    light = UsdLux.SphereLight.Define(stage, path)
    light.CreateRadiusAttr(float(radius))
    if intensity is not None:
        light.CreateIntensityAttr(float(intensity))
    _place(light, pos)
    return light


def add_cylinder_light(stage: Usd.Stage, path: str, pos, length: float, radius: float, *, treat_as_line: bool | None = None,
                       intensity: float | None = None) -> UsdLux.CylinderLight:
    """A CylinderLight of ``length`` along its local X and ``radius`` at ``pos`` (a point, or a
    Gf.Matrix4d); ``treat_as_line``: author ``treatAsLine``."""
    light = UsdLux.CylinderLight.Define(stage, path)
    light.CreateLengthAttr(float(length))
    light.CreateRadiusAttr(float(radius))
    if treat_as_line is not None:
        light.CreateTreatAsLineAttr(bool(treat_as_line))
    if intensity is not None:
        light.CreateIntensityAttr(float(intensity))
    _place(light, pos)
    return light


def add_point_light(stage: Usd.Stage, path: str, pos, *, intensity: float | None = None,
                    radius: float | None = None) -> UsdLux.SphereLight:
    """A SphereLight treated as a point (``treatAsPoint``) at ``pos``; ``radius``: authored when given."""
    light = UsdLux.SphereLight.Define(stage, path)
    if radius is not None:
        light.CreateRadiusAttr(float(radius))
    light.CreateTreatAsPointAttr(True)
    if intensity is not None:
        light.CreateIntensityAttr(float(intensity))
    _place(light, pos)
    return light


def add_sun(stage: Usd.Stage, path: str, angle: float, rotate=(0.0, -45.0, 0.0), *, intensity: float | None = None,
            toward=None) -> UsdLux.DistantLight:
    """A DistantLight of full cone angle ``angle`` (degrees), rotated by ``rotate`` (XYZ degrees);
    or, with ``toward``, aimed so that its light arrives from that direction (it emits along
    −``toward``; a look-at transform, ``rotate`` unused)."""
    sun = UsdLux.DistantLight.Define(stage, path)
    sun.CreateAngleAttr(float(angle))
    if intensity is not None:
        sun.CreateIntensityAttr(float(intensity))
    if toward is None:
        sun.AddRotateXYZOp().Set(Gf.Vec3f(*rotate))
    else:
        t = np.asarray(toward, float)
        t /= np.linalg.norm(t)
        up = (0.0, 1.0, 0.0) if abs(t[2]) > 0.9 else (0.0, 0.0, 1.0)
        sun.AddTransformOp().Set(look_at_xform(t * 100.0, (0.0, 0.0, 0.0), up))
    return sun


def look_at_xform(eye: Sequence[float], target: Sequence[float], up: Sequence[float]) -> Gf.Matrix4d:
    """Local-to-world matrix of an object at `eye` whose local -Z looks at
    `target` with local +Y as close as possible to `up`."""
    view = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(*up))
    return view.GetInverse()


def world_dir(prim: Usd.Prim, d=(0.0, 0.0, -1.0)) -> Gf.Vec3d:
    """The prim's local direction ``d`` in world space (default time), normalised."""
    m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    return m.TransformDir(Gf.Vec3d(*d)).GetNormalized()


def check_points_down(prim: Usd.Prim, down: Sequence[float], min_cos: float = 0.5) -> None:
    """Raise unless the prim's world −Z is within ``acos(min_cos)`` of ``down``."""
    d = world_dir(prim)
    c = float(Gf.Dot(d, Gf.Vec3d(*down)))
    if c < min_cos:
        raise RuntimeError("%s: world -Z = %s does not point down (cos=%.3f)"
                           % (prim.GetPath(), d, c))


# --------------------------------------------------------------------------- cameras


def add_camera(stage: Usd.Stage, path: str, eye, target, up=(0, 0, 1), focal: float = 18.0, *,
               aperture=(20.955, 20.955), clip=(0.01, 1000.0), projection: bool = False) -> UsdGeom.Camera:
    """A camera at ``eye`` looking at ``target`` (a look-at transform: local −Z forward, +Y toward
    ``up``); focal length and apertures in mm; ``projection``: author ``perspective``."""
    cam = UsdGeom.Camera.Define(stage, path)
    if projection:
        cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    cam.CreateFocalLengthAttr(float(focal))
    cam.CreateHorizontalApertureAttr(float(aperture[0]))
    cam.CreateVerticalApertureAttr(float(aperture[1]))
    cam.CreateClippingRangeAttr(Gf.Vec2f(float(clip[0]), float(clip[1])))
    cam.AddTransformOp().Set(look_at_xform(eye, target, up))
    return cam


# --------------------------------------------------------------------------- instances


def add_class_root(stage: Usd.Stage, path: str = "/Prototypes") -> Usd.Prim:
    """An abstract ``class`` Scope to hold prototypes (never rendered itself)."""
    root = stage.CreateClassPrim(path)
    root.SetTypeName("Scope")
    return root


def add_instance(stage: Usd.Stage, path: str, proto: str, translate, rotate_z: float = 0.0, scale=1.0) -> UsdGeom.Xform:
    """An instanceable Xform referencing the prim ``proto`` of the same stage: translate, rotateZ
    (degrees) and scale (a number: uniform; or three)."""
    inst = UsdGeom.Xform.Define(stage, path)
    prim = inst.GetPrim()
    prim.GetReferences().AddInternalReference(Sdf.Path(proto))
    prim.SetInstanceable(True)
    inst.AddTranslateOp().Set(Gf.Vec3d(*map(float, translate)))
    inst.AddRotateZOp().Set(float(rotate_z))
    s = (scale, scale, scale) if np.ndim(scale) == 0 else scale
    inst.AddScaleOp().Set(Gf.Vec3f(*map(float, s)))
    return inst


# --------------------------------------------------------------------------- attributes


def set_doc_attr(prim: Usd.Prim, name: str, value: float) -> None:
    """A custom double attribute."""
    attr = prim.CreateAttribute(name, Sdf.ValueTypeNames.Double, custom=True)
    attr.Set(float(value))


def set_doc_string(prim: Usd.Prim, name: str, value: str) -> None:
    """A custom string attribute (``wsoft:doc``: what a stage holds, in words)."""
    prim.CreateAttribute(name, Sdf.ValueTypeNames.String, custom=True).Set(value)


def set_custom_bool(prim: Usd.Prim, name: str, value: bool) -> None:
    """A custom bool attribute (``wsoft:dynamic``, ``wsoft:torch``)."""
    prim.CreateAttribute(name, Sdf.ValueTypeNames.Bool, custom=True).Set(bool(value))


def set_display_color(mesh: UsdGeom.Mesh, color: Sequence[float]) -> None:
    """A constant ``primvars:displayColor``."""
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(
        Vt.Vec3fArray([Gf.Vec3f(*map(float, color))]))


def mark_casters(stage: Usd.Stage, paths: Sequence[str]) -> None:
    """Mark the occluders of a test scene as the *dynamic casters* of Salzman's method
    (``wsoft:dynamic = true``); the ground stays a static receiver. Other techniques ignore it."""
    for path in paths:
        set_custom_bool(stage.GetPrimAtPath(path), "wsoft:dynamic", True)
