"""The corpus's cases of material bindings and purposes: full-purpose bindings, render settings whose purposes leave nothing."""

from __future__ import annotations

from wsoft.stages.adversarial.checks import all_lit
from wsoft.stages.adversarial.common import Case, _base, _save

CASES: list[Case] = []
BASES: dict = {}


def opacity_material(st, path: str, opacity: float):
    """A UsdPreviewSurface material of constant ``opacity`` with ``opacityThreshold`` 0.5 (a cutout
    where ``opacity`` is below it)."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(st, path)
    surf = UsdShade.Shader.Define(st, path + "/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(opacity)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def b_full_purpose_cutout(folder: str) -> str:
    """The base's occluder bound to an opaque material for all purposes and, through
    ``material:binding:full``, to a material cut out everywhere (opacity 0): a final-frame
    renderer resolves the ``full`` binding, so nothing casts."""
    from pxr import UsdShade

    st = _base()
    opaque = opacity_material(st, "/World/Looks/Opaque", 1.0)
    cut = opacity_material(st, "/World/Looks/Cut", 0.0)
    binding = UsdShade.MaterialBindingAPI.Apply(st.GetPrimAtPath("/World/Occluder"))
    binding.Bind(opaque)
    binding.Bind(cut, materialPurpose=UsdShade.Tokens.full)
    return _save(st, folder, "full_purpose_cutout")


CASES.append(Case("full_purpose_cutout", b_full_purpose_cutout, check=all_lit, silent_hazard=True,
                  note="occluder bound opaque for all purposes and to a fully cut-out material for the full purpose: nothing casts"))
