"""The corpus's cases of animation a sequence must follow: splines, instances under an animated light, point velocities."""

from __future__ import annotations

from wsoft.stages.adversarial.checks import close_to
from wsoft.stages.adversarial.common import Case, _base, _save


def _quiet_save(st, folder: str, name: str) -> str:
    """:func:`_save`, with usd-core's writer's warning about splines' deprecated inner loops kept off stderr."""
    from pxr import UsdUtils

    d = UsdUtils.CoalescingDiagnosticDelegate()
    try:
        return _save(st, folder, name)
    finally:
        d.TakeUncoalescedDiagnostics()


def b_occluder_y2(folder):
    """The base with the occluder moved 2 along Y, nothing animated, marked ``wsoft:dynamic``: where
    the spline and the velocities below put it, a dynamic caster as they make it."""
    from pxr import UsdGeom

    from pxr import Sdf

    st = _base()
    occ = st.GetPrimAtPath("/World/Occluder")
    UsdGeom.Xformable(occ).AddTranslateYOp().Set(2.0)
    occ.CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)  # a dynamic caster, as the animated one is
    return _save(st, folder, "occluder_y2")


def b_spline_occluder(folder):
    """The base with the occluder's translateY authored only as a spline (0 at 0, linear to 2 at
    10), no time sample and no time range."""
    from pxr import Ts, UsdGeom

    st = _base()
    sp = Ts.Spline("double")
    for t, v in ((0.0, 0.0), (10.0, 2.0)):
        sp.SetKnot(Ts.Knot(typeName="double", time=t, value=v, nextInterp=Ts.InterpLinear))
    UsdGeom.Xformable(st.GetPrimAtPath("/World/Occluder")).AddTranslateYOp().GetAttr().SetSpline(sp)
    return _quiet_save(st, folder, "spline_occluder")


def _lamp_with_shade(moving: bool):
    """The base's light at (3, 0, 3) (``moving``: time-sampled from (-3, 0, 3) at 0, a time range
    0..10; else marked ``wsoft:dynamic``, as the moving one is) with a lamp shade below it: an
    instanceable reference to a 3 x 3 plate 0.25 under the light."""
    from pxr import Gf, Sdf, UsdGeom

    from wsoft.stages.builders import add_class_root, add_instance, add_quad

    st = _base()
    add_class_root(st, "/Prototypes")
    add_quad(st, "/Prototypes/Shade/Plate", (0, 0, 0), 1.5)
    add_instance(st, "/World/Light/Shade", "/Prototypes/Shade", (0, 0, -0.25))
    (op,) = UsdGeom.Xformable(st.GetPrimAtPath("/World/Light")).GetOrderedXformOps()
    if moving:
        op.GetAttr().ClearDefault()
        op.Set(Gf.Vec3d(-3, 0, 3), 0.0)
        op.Set(Gf.Vec3d(3, 0, 3), 10.0)
        st.SetStartTimeCode(0)
        st.SetEndTimeCode(10)
    else:
        op.Set(Gf.Vec3d(3, 0, 3))
        st.GetPrimAtPath("/World/Light").CreateAttribute("wsoft:dynamic", Sdf.ValueTypeNames.Bool).Set(True)
    return st


def b_lamp_shade_still(folder):
    return _save(_lamp_with_shade(False), folder, "lamp_shade_still")


def b_lamp_shade_moving(folder):
    return _save(_lamp_with_shade(True), folder, "lamp_shade_moving")


def b_velocity_points(folder):
    """The base with the occluder's points time-sampled at 0 (the base's) and 10 (2 along Y), each
    with ``velocities`` of 9.6 units/s along Y at 24 time codes per second (0.4 per time code): at 5
    USD extrapolates from the sample at 0 to 2 along Y, where interpolating the samples gives 1."""
    from pxr import Gf, UsdGeom

    st = _base()
    st.SetTimeCodesPerSecond(24)
    mesh = UsdGeom.Mesh(st.GetPrimAtPath("/World/Occluder"))
    pts = list(mesh.GetPointsAttr().Get())
    mesh.GetPointsAttr().ClearDefault()
    for t in (0.0, 10.0):
        mesh.GetPointsAttr().Set([Gf.Vec3f(q[0], q[1] + 0.2 * t, q[2]) for q in pts], t)
        mesh.GetVelocitiesAttr().Set([Gf.Vec3f(0, 9.6, 0)] * len(pts), t)
    return _save(st, folder, "velocity_points")


def b_still_no_range(folder):
    """The base: nothing animated, no time range."""
    return _save(_base(), folder, "still_no_range")


CASES: list[Case] = [
    # 0.02: rtdenoise draws new samples each frame of a sequence (its frame 10 against the still stage's frame: 0.013 of
    # noise at 48 x 36); the geometry of the wrong frame gives 0.06-0.10
    Case("spline_occluder", b_spline_occluder, check=close_to("occluder_y2", 0.02), silent_hazard=True,
         args=("--frames", "0:10:10"), judged_time=10.0,
         note="translateY a spline only (0 at 0, 2 at 10), no time sample or range: frame 10 has the occluder at 2"),
    Case("instanced_shade_moving_light", b_lamp_shade_moving, check=close_to("lamp_shade_still", 0.01), silent_hazard=True,
         args=("--frames", "0:10:10"), judged_time=10.0,
         note="a lamp's shade, an instance below its time-sampled light, moves with it: frame 10 as the still lamp there"),
    Case("velocity_points", b_velocity_points, check=close_to("occluder_y2", 0.02), silent_hazard=True,
         args=("--frames", "0:5:5"), judged_time=5.0,
         note="points sampled at 0 and 10 with velocities: at 5 where USD extrapolates them (2 along Y), not the samples' midpoint"),
    Case("frames_without_time_range", b_still_no_range, "error", ("has no time range",),
         args=("--frames", "100:200"), note="a still stage without a time range: --frames is refused before rendering"),
]
BASES: dict = {"occluder_y2": b_occluder_y2, "lamp_shade_still": b_lamp_shade_still}
