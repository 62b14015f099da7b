"""The USD pipeline stages of ``wsoft bench usd-pipeline``: UsdRender settings and a light's shadowLink.

* :func:`render_settings_stage` — two cameras over a few blockers, and a ``RenderSettings`` prim,
  named by the stage metadata ``renderSettingsPrimPath``, that picks the *second* camera at a
  non-default resolution with wide pixels (``pixelAspectRatio`` 4/3), ``cropAperture`` and a data
  window, and a product whose ``visibility`` RenderVar receives ``V``.
* :func:`shadow_link_stage` — a light over two blockers, with or without a ``collection:shadowLink``
  that excludes blocker B.
"""

from __future__ import annotations

from pxr import Gf, Sdf, UsdLux, UsdRender

from wsoft.stages.builders import add_box, add_camera, add_quad, add_rect_light, make_stage

RS_PRIM = "/Render/Settings"
PIXEL_ASPECT = 4.0 / 3.0  # a 1.33x anamorphic squeeze
DATA_WINDOW = (0.0, 0.1, 1.0, 0.9)  # NDC: the middle 80% of the rows
CONFORM = "cropAperture"
CAM_APERTURE = (36.0, 20.25)  # mm, 16:9
LINK_BLOCKERS = {"A": -1.2, "B": 1.2}  # x of the blockers (height 1, half side 0.4) under a 1 x 1 light at height 3
LINK_LIGHT_Z, LINK_BLOCKER_Z, LINK_HALF = 3.0, 1.0, 0.4


def render_settings_stage(resolution):
    """Two cameras over a few blockers; RenderSettings of ``resolution`` picking the second one
    (see the module), in memory."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Tower", (-0.4, -0.4, 0.0), (0.4, 0.4, 1.6))
    add_box(st, "/World/Crate", (1.2, 0.8, 0.0), (2.2, 1.6, 0.5))
    add_quad(st, "/World/Sheet", (-1.7, 1.3, 1.2), 0.5)
    add_rect_light(st, "/World/Light", (0.6, -0.8, 4.0), 1.5, 1.5)
    for path_, eye in (("/World/Cam1", (0.0, -8.0, 4.0)), ("/World/Cam2", (6.5, 4.5, 4.5))):
        cam = add_camera(st, path_, eye, (0.0, 0.3, 0.5), focal=24.0)
        cam.GetHorizontalApertureAttr().Set(CAM_APERTURE[0])
        cam.GetVerticalApertureAttr().Set(CAM_APERTURE[1])
    rs = UsdRender.Settings.Define(st, RS_PRIM)
    rs.CreateResolutionAttr(Gf.Vec2i(*resolution))
    rs.CreateCameraRel().SetTargets(["/World/Cam2"])
    rs.CreatePixelAspectRatioAttr(PIXEL_ASPECT)
    rs.CreateAspectRatioConformPolicyAttr(CONFORM)
    rs.CreateDataWindowNDCAttr(Gf.Vec4f(*DATA_WINDOW))
    var = UsdRender.Var.Define(st, "/Render/Vars/shadowVis")
    var.CreateSourceNameAttr("visibility")
    prod = UsdRender.Product.Define(st, "/Render/Products/shadowPass")
    prod.CreateProductNameAttr("shadow_pass.exr")
    prod.CreateOrderedVarsRel().SetTargets([var.GetPath()])
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    st.SetMetadata("renderSettingsPrimPath", RS_PRIM)
    st.GetRootLayer().documentation = ("Built by wsoft bench usd-pipeline: two cameras; the render settings (named by the stage "
                                       "metadata renderSettingsPrimPath) pick /World/Cam2 with wide pixels, cropAperture and a data window.")
    return st


def shadow_link_stage(exclude: bool):
    """A ground and blockers A and B under a 1 x 1 rect light, in memory; ``exclude``: the light's
    ``collection:shadowLink`` excludes ``/World/BlockerB``."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    for name, x in LINK_BLOCKERS.items():
        add_quad(st, f"/World/Blocker{name}", (x, 0, LINK_BLOCKER_Z), LINK_HALF)
    light = add_rect_light(st, "/World/Light", (0, 0, LINK_LIGHT_Z), 1.0, 1.0)
    if exclude:
        UsdLux.LightAPI(light.GetPrim()).GetShadowLinkCollectionAPI().GetExcludesRel().AddTarget(Sdf.Path("/World/BlockerB"))
    add_camera(st, "/World/Cam", (0, -7, 6), (0, 0, 0), focal=18.0)
    return st
