"""The corpus's case of a shaped light (``UsdLux.ShapingAPI``): a spot whose cone leaves a box out."""

from __future__ import annotations

import numpy as np

from wsoft.stages.adversarial.common import Case, _save

CASES: list[Case] = []
BASES: dict = {}

SPOT = (0.0, 0.0, 3.0)  # a sphere light of radius 0.1 facing down, its cone 30 degrees off its axis
SPOT_CONE = 30.0
BOX_X = (3.5, 4.1)  # a box 49 to 56 degrees off the spot's axis: outside its cone


def b_spot_box_outside(folder: str) -> str:
    """A ground +-5, a sphere light (radius 0.1) 3 above its centre facing down with a 30-degree
    ``shaping:cone:angle``, and a 0.6 x 0.6 x 0.6 box at x 3.5..4.1, outside the cone: nothing in the
    cone casts, and the box's would-be shadow lies where the spot sends no light."""
    from pxr import UsdLux

    from wsoft.stages.builders import add_box, add_camera, add_quad, add_sphere_light, make_stage

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_box(st, "/World/Box", (BOX_X[0], -0.3, 0.0), (BOX_X[1], 0.3, 0.6))
    light = add_sphere_light(st, "/World/Light", SPOT, 0.1)
    UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingConeAngleAttr(SPOT_CONE)
    add_camera(st, "/World/Cam", (0, -7, 6), (0.5, 0, 0))
    return _save(st, folder, "spot_box_outside")


def box_left_out(ch, base=None, technique="") -> str | None:
    """Ground pixels past the box's near face (its would-be shadow and beyond) are outside the reach
    mask and show the ambient alone; ground pixels the cone reaches all have V >= 0.95 (nothing in
    the cone casts)."""
    g = (ch["A"] > 0) & (np.abs(ch["P.Z"]) < 1e-4)
    reach = ch.get("reach.Light")
    if reach is None:
        return "no reach.Light channel"
    beyond = g & (ch["P.X"] > BOX_X[0])
    lit = g & (reach > 0)
    if beyond.sum() < 20 or lit.sum() < 20:
        return f"{int(beyond.sum())} ground pixels beyond the box, {int(lit.sum())} in the cone"
    if (reach[beyond] > 0).any():
        return f"{int((reach[beyond] > 0).sum())} ground pixels beyond the box marked reached by a 30-degree cone"
    if np.ptp(ch["R"][beyond]) > 1e-6:
        return "ground beyond the box is not uniformly ambient: the spot lights it"
    v = ch["V"][lit]
    return None if v.min() >= 0.95 else f"V {v.min():.3f} in the cone, where nothing casts (want >= 0.95)"


CASES.append(Case("spot_box_outside", b_spot_box_outside, check=box_left_out, silent_hazard=True,
                  note="a 30-degree spot (ShapingAPI) with a box outside its cone: the box's would-be shadow is masked "
                       "(reach.Light), unlit, and warned of by no technique"))
