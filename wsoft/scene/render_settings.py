"""UsdRender settings: which ``RenderSettings`` prim a render uses, read once into a frozen
:class:`RenderSettings` on the :class:`~wsoft.scene.types.Scene`.

**Which prim** (as ``usdrecord`` picks it): the one asked for (``--render-settings PATH``,
``render_settings=`` in Python; anything but a RenderSettings prim there is an error), else the
stage metadata ``renderSettingsPrimPath`` (a path naming no RenderSettings prim is a warning and
is passed over), else ``UsdRender.Settings.GetStageRenderSettings(stage)``, else none. usd-core
0.26's ``GetStageRenderSettings`` reads that same metadata, so the third step finds something
only where a USD build adds a fallback of its own; :attr:`RenderSettings.source` says which step
found the prim.

**What is read**, with ``UsdRender.SettingsBase``'s own attributes and fallbacks: ``resolution``,
the ``camera`` relationship (one target, a camera), ``pixelAspectRatio``,
``aspectRatioConformPolicy``, ``dataWindowNDC``, and the settings' ``includedPurposes`` (which
geometry the loader reads); the ``products`` with their ``productName`` and ``orderedVars``. The
*output product* is the first product whose ``orderedVars`` hold a RenderVar named ``visibility``
or with ``sourceName = "visibility"``: the frame's ``V`` channel is written under that var's
name, its ``productName`` is the default output path, and what it authors itself (resolution,
camera, ...) overrides the settings' values, as ``UsdRenderComputeSpec`` applies a product's
opinions over its settings.

Bad values are one-line :class:`~wsoft.errors.SceneError` s naming the file and the prim that
authored them: a resolution that is not positive, a ``pixelAspectRatio`` that is not a finite
number > 0, a ``dataWindowNDC`` that is empty, inverted or not finite, an unknown conform policy,
and a ``camera`` relationship authored with no target, with several, or targeting something that
is not a camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wsoft.errors import SceneError

SOURCES = ("flag", "metadata", "GetStageRenderSettings", "none")
"""Where the settings prim came from (:attr:`RenderSettings.source`; ``none``: no settings)."""

CONFORM_POLICIES = ("expandAperture", "cropAperture", "adjustApertureWidth", "adjustApertureHeight", "adjustPixelAspectRatio")
"""UsdRender's ``aspectRatioConformPolicy`` values (the fallback is ``expandAperture``)."""

DEFAULT_PURPOSES = ("default", "render")
"""UsdRender's fallback ``includedPurposes``, and what the loader reads without settings."""

KNOWN_PURPOSES = ("default", "render", "proxy", "guide")

VISIBILITY = "visibility"
"""The RenderVar name (or ``sourceName``) that receives wsoft's ``V`` channel."""

FULL_WINDOW = (0.0, 0.0, 1.0, 1.0)

# the frame's own channels (README, "Output contract"): a visibility var may not take one of these names
_CHANNELS = frozenset({"V_stderr", "P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "Z", "A", "R", "G", "B"})


@dataclass(frozen=True)
class RenderProduct:
    """A ``RenderProduct`` the settings list."""

    path: str
    """The product prim."""
    product_name: str
    """``productName`` (an output path; ``""`` when unauthored)."""
    visibility_var: str | None
    """The name (prim name) of its RenderVar named ``visibility`` or with ``sourceName`` ``visibility``:
    the EXR channel ``V`` is written under it. None when it has none."""
    visibility_var_path: str | None
    """That RenderVar's prim path."""


@dataclass(frozen=True)
class RenderSettings:
    """The render settings a scene was loaded with: the effective values (the output product's
    authored opinions over the settings prim's, fallbacks where neither authors one)."""

    path: str
    """The RenderSettings prim."""
    source: str
    """How it was chosen: ``flag`` (asked for), ``metadata`` (``renderSettingsPrimPath``) or
    ``GetStageRenderSettings`` (see :data:`SOURCES`)."""
    resolution: tuple[int, int]
    """Image width and height in pixels (fallback 2048 x 1080)."""
    camera: str | None
    """The camera prim the ``camera`` relationship targets; None when unauthored."""
    camera_from: str | None
    """The prim whose ``camera`` relationship gave :attr:`camera` (the settings or the output product)."""
    pixel_aspect: float
    """``pixelAspectRatio``: a pixel's width over its height (> 0)."""
    conform_policy: str
    """``aspectRatioConformPolicy``, one of :data:`CONFORM_POLICIES`."""
    data_window: tuple[float, float, float, float]
    """``dataWindowNDC`` (xmin, ymin, xmax, ymax): the rendered region in NDC of the full image,
    (0, 0) its lower-left corner and (1, 1) its upper-right."""
    included_purposes: tuple[str, ...]
    """``includedPurposes``: the ``UsdGeomImageable`` purposes whose prims are loaded."""
    products: tuple[RenderProduct, ...]
    """Every RenderProduct of the ``products`` relationship, in order."""
    product: str | None
    """The output product's path (the first with a visibility var), or None."""

    @property
    def output(self) -> RenderProduct | None:
        """The output product (see :attr:`product`)."""
        return next((p for p in self.products if p.path == self.product), None)

    @property
    def has_data_window(self) -> bool:
        return self.data_window != FULL_WINDOW


def data_window_pixels(ndc: tuple[float, float, float, float], width: int, height: int) -> tuple[int, int, int, int]:
    """The pixels of a ``width x height`` image that ``dataWindowNDC`` ``ndc`` covers, as
    (x0, y0, x1, y1), half-open, rows counted from the top: columns ``round(xmin W) ..
    round(xmax W)``, rows ``round((1 - ymax) H) .. round((1 - ymin) H)`` (hdPrman's rounding),
    clipped to the image. Empty (x0 == x1 or y0 == y1) when the window selects no pixel."""
    xmin, ymin, xmax, ymax = ndc
    x0 = min(max(int(round(xmin * width)), 0), width)
    x1 = min(max(int(round(xmax * width)), x0), width)
    y0 = min(max(int(round((1.0 - ymax) * height)), 0), height)
    y1 = min(max(int(round((1.0 - ymin) * height)), y0), height)
    return x0, y0, x1, y1


def select_settings_prim(reader, requested: str | None):
    """The RenderSettings prim to use and where it came from: (prim or None, source)."""
    from pxr import Sdf, UsdRender

    stage = reader.stage
    if requested is not None:
        path = str(requested)
        if not Sdf.Path.IsValidPathString(path) or not Sdf.Path(path).IsAbsolutePath():
            raise SceneError(f"render settings {path!r}: not an absolute prim path", file=reader.file)
        prim = stage.GetPrimAtPath(path)
        if not prim:
            raise SceneError("no prim here: the requested render settings do not exist", file=reader.file, prim=path)
        if not prim.IsA(UsdRender.Settings):
            raise SceneError(f"requested render settings: a {prim.GetTypeName() or 'typeless'} prim, not a RenderSettings prim",
                             file=reader.file, prim=path)
        return prim, "flag"
    meta = stage.GetMetadata("renderSettingsPrimPath") if stage.HasAuthoredMetadata("renderSettingsPrimPath") else ""
    if meta:
        prim = stage.GetPrimAtPath(meta) if Sdf.Path.IsValidPathString(meta) and Sdf.Path(meta).IsAbsolutePath() else None
        if prim and prim.IsA(UsdRender.Settings):
            return prim, "metadata"
        reader.warn(None, f"stage metadata renderSettingsPrimPath = {meta!r} names no RenderSettings prim; ignored")
    rs = UsdRender.Settings.GetStageRenderSettings(stage)
    if rs:
        return rs.GetPrim(), "GetStageRenderSettings"
    return None, "none"


def read_render_settings(reader, requested: str | None = None) -> tuple[RenderSettings | None, str]:
    """The render settings of ``reader``'s stage (a :class:`~wsoft.scene.usd_context.StageContext`: its
    stage, file, time code, ``err`` and ``warn``), chosen as the module says: (settings or None,
    source)."""
    from pxr import UsdRender

    prim, source = select_settings_prim(reader, requested)
    if prim is None:
        return None, source
    settings = UsdRender.Settings(prim)
    values = _read_base(reader, UsdRender.SettingsBase(prim), authored_only=False)
    values["camera_from"] = str(prim.GetPath()) if values["camera"] else None

    products, output = [], None
    for target in settings.GetProductsRel().GetForwardedTargets():
        p = reader.stage.GetPrimAtPath(target)
        if not p or not p.IsA(UsdRender.Product):
            reader.warn(prim, f"products: {target} is not a RenderProduct; skipped")
            continue
        product = _read_product(reader, p)
        products.append(product)
        if product.visibility_var is None:
            continue
        if output is None:
            output = product
            over = _read_base(reader, UsdRender.SettingsBase(p), authored_only=True)
            if over.get("camera"):
                over["camera_from"] = product.path
            values.update({k: v for k, v in over.items() if v is not None})
        else:
            reader.warn(p, f"a second product with a {VISIBILITY} RenderVar: only the first, {output.path}, is written")

    purposes = tuple(str(t) for t in (settings.GetIncludedPurposesAttr().Get() or ()))
    unknown = [t for t in purposes if t not in KNOWN_PURPOSES]
    if unknown:
        reader.warn(prim, f"includedPurposes: unknown purpose(s) {', '.join(unknown)} (known: {', '.join(KNOWN_PURPOSES)})")
    if len(unknown) == len(purposes):
        raise reader.err(prim, f"includedPurposes = [{', '.join(purposes)}] includes no purpose wsoft knows, so these render settings "
                               f"leave nothing to draw (no mesh, no light); include some of {', '.join(KNOWN_PURPOSES)} "
                               "(unauthored: default, render)")
    return RenderSettings(path=str(prim.GetPath()), source=source, included_purposes=purposes, products=tuple(products),
                          product=output.path if output else None, **values), source


def _read_base(reader, base, *, authored_only: bool) -> dict:
    """The ``UsdRender.SettingsBase`` values of a settings or product prim, checked; with
    ``authored_only`` the unauthored ones are None (a product's overrides)."""
    prim = base.GetPrim()

    def value(attr):
        if authored_only and not attr.HasAuthoredValue():
            return None
        return attr.Get(reader.timecode)

    out: dict = {"camera": _camera_target(reader, base)}
    res = value(base.GetResolutionAttr())
    if res is not None:
        w, h = int(res[0]), int(res[1])
        if w <= 0 or h <= 0:
            raise reader.err(prim, f"resolution = ({w}, {h}) must be positive")
        out["resolution"] = (w, h)
    par = value(base.GetPixelAspectRatioAttr())
    if par is not None:
        par = float(par)
        if not math.isfinite(par) or par <= 0:
            raise reader.err(prim, f"pixelAspectRatio = {par:g} must be a finite number > 0")
        out["pixel_aspect"] = par
    policy = value(base.GetAspectRatioConformPolicyAttr())
    if policy is not None:
        if str(policy) not in CONFORM_POLICIES:
            raise reader.err(prim, f"aspectRatioConformPolicy = {str(policy)!r} is not one of {', '.join(CONFORM_POLICIES)}")
        out["conform_policy"] = str(policy)
    win = value(base.GetDataWindowNDCAttr())
    if win is not None:
        w4 = tuple(float(x) for x in win)
        if not all(math.isfinite(x) for x in w4):
            raise reader.err(prim, f"dataWindowNDC = {w4} is not finite")
        if not (w4[0] < w4[2] and w4[1] < w4[3]):
            raise reader.err(prim, f"dataWindowNDC = ({w4[0]:g}, {w4[1]:g}, {w4[2]:g}, {w4[3]:g}) is empty or inverted "
                                   "(need xmin < xmax and ymin < ymax)")
        if min(w4) < 0.0 or max(w4) > 1.0:
            reader.warn(prim, "dataWindowNDC reaches outside [0, 1] (overscan): wsoft renders only the image, the window is clipped to it")
        out["data_window"] = w4
    return out


def _camera_target(reader, base) -> str | None:
    """The camera a settings or product prim's ``camera`` relationship targets (None when it authors
    no targets); no target, several, or a non-camera target are errors."""
    from pxr import UsdGeom

    prim = base.GetPrim()
    rel = base.GetCameraRel()
    if not rel or not rel.HasAuthoredTargets():
        return None
    targets = rel.GetForwardedTargets()
    if len(targets) != 1:
        listed = f": {', '.join(str(t) for t in targets)}" if targets else ""
        raise reader.err(prim, f"camera relationship has {len(targets)} targets{listed}; it needs exactly one camera")
    cam = reader.stage.GetPrimAtPath(targets[0])
    if not cam:
        raise reader.err(prim, f"camera relationship targets {targets[0]}, which does not exist")
    if not cam.IsA(UsdGeom.Camera):
        raise reader.err(prim, f"camera relationship targets {targets[0]}, a {cam.GetTypeName() or 'typeless'} prim, not a Camera")
    return str(targets[0])


def _read_product(reader, prim) -> RenderProduct:
    from pxr import UsdRender

    product = UsdRender.Product(prim)
    name = product.GetProductNameAttr().Get(reader.timecode)
    var_name = var_path = None
    for target in product.GetOrderedVarsRel().GetForwardedTargets():
        v = reader.stage.GetPrimAtPath(target)
        if not v or not v.IsA(UsdRender.Var):
            reader.warn(prim, f"orderedVars: {target} is not a RenderVar; skipped")
            continue
        source = UsdRender.Var(v).GetSourceNameAttr().Get(reader.timecode)
        if var_name is None and (v.GetName() == VISIBILITY or str(source or "") == VISIBILITY):
            var_name, var_path = v.GetName(), str(v.GetPath())
    if var_name is not None and (var_name in _CHANNELS or var_name.startswith(("V.", "V_stderr.", "reach."))):
        raise reader.err(reader.stage.GetPrimAtPath(var_path), f"RenderVar name {var_name!r} is already one of the frame's channels; rename the var")
    return RenderProduct(path=str(prim.GetPath()), product_name=str(name or ""), visibility_var=var_name, visibility_var_path=var_path)
