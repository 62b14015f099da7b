"""The corpus's cases, the stages they compare with, and :func:`judge`."""

from __future__ import annotations

import contextlib
from typing import Callable

from wsoft.stages.adversarial.checks import (
    all_dark, all_lit, close_to, far_side_dark, ground_dark, same_as, same_as_base, sky_over_square, sun_wall_penumbra,
)
from wsoft.stages.adversarial.gaps import BASES as GAP_BASES
from wsoft.stages.adversarial.gaps import CASES as GAP_CASES
from wsoft.stages.adversarial.gaps import KNOWN as GAP_KNOWN
from wsoft.stages.adversarial.lights import BASES as LIGHT_BASES
from wsoft.stages.adversarial.lights import CASES as LIGHT_CASES
from wsoft.stages.adversarial.materials import BASES as MATERIAL_BASES
from wsoft.stages.adversarial.materials import CASES as MATERIAL_CASES
from wsoft.stages.adversarial.receivers import BASES as RECEIVER_BASES
from wsoft.stages.adversarial.receivers import CASES as RECEIVER_CASES
from wsoft.stages.adversarial.sequences import BASES as SEQUENCE_BASES
from wsoft.stages.adversarial.sequences import CASES as SEQUENCE_CASES
from wsoft.stages.adversarial.shaping import BASES as SHAPING_BASES
from wsoft.stages.adversarial.shaping import CASES as SHAPING_CASES
from wsoft.stages.adversarial.common import Case, Result
from wsoft.stages.adversarial.geometry import (
    b_base, b_base_dynamic, b_base_sun, b_broken_syntax, b_camera_inside, b_concave_pentagon, b_concave_pentagon_split,
    b_count_5_minus_2, b_cutout_16bit, b_cutout_1x1, b_cutout_8bit, b_cutout_palette, b_cutout_truncated_png, b_cutout_usdz,
    b_disk_inf_radius, b_disk_negative_radius, b_dome_only, b_empty, b_exposure_huge, b_far_light_100, b_far_light_1e4, b_far_origin_xy,
    b_far_origin_z, b_hole_face, b_huge_far_triangle, b_huge_far_triangle_sun, b_inf_transform, b_inverted_clip, b_lamp_rect,
    b_lamp_sphere, b_light_below_ground, b_light_on_receiver_plane, b_mirrored, b_missing_reference, b_missing_sublayer,
    b_nan_transform, b_negative_count, b_no_occluder, b_point_3e38, b_points_1e30, b_rect_inf_width, b_rect_nan_width, b_room_ceiling,
    b_sphere, b_sphere_nan_radius, b_thin_plate_behind, b_time_samples_only, b_tiny_cutout, b_tiny_scene, b_usdc, b_zero_area,
    b_zero_width_rect,
)
from wsoft.stages.adversarial.surfaces import (
    b_cutout_clamp, b_cutout_exr, b_cutout_scale_bias, b_cutout_transform2d, b_cutout_udim, b_cutout_varname_uv, b_disk_facing_away,
    b_light_facing_away, b_light_inverted, b_light_scaled_away, b_sun_far_wall, b_sun_huge_far_wall,
)

CASES: list[Case] = [
    Case("lamp_rect", b_lamp_rect, check=all_dark, silent_hazard=True, map_size=1024,
         note="rect light inside a closed box (lamp shade); 1024² maps (at 256² essm/vssm leak 0.09-0.10 at the shade's rim)"),
    Case("lamp_sphere", b_lamp_sphere, check=all_dark, silent_hazard=True, map_size=1024,
         note="sphere light inside a closed box: its receivers all around it, beyond a single frustum (a cube map); 1024² maps, as lamp_rect"),
    Case("huge_far_triangle", b_huge_far_triangle, check=same_as_base, silent_hazard=True, note="one triangle with corners at +-1e7, out of view"),
    Case("huge_far_triangle_sun", b_huge_far_triangle_sun, check=same_as_base, base="base_sun", silent_hazard=True,
         note="the same under a 2-degree sun"),
    Case("point_3e38", b_point_3e38, check=same_as_base, silent_hazard=True, note="a sliver triangle reaching 3e38"),
    Case("points_1e30", b_points_1e30, check=same_as_base, note="a triangle at 1e30"),
    Case("thin_plate_behind", b_thin_plate_behind, check=all_dark, silent_hazard=True, note="double-sided plate lit from behind"),
    Case("sphere", b_sphere, check=far_side_dark, silent_hazard=True, note="closed sphere: far side dark, top lit"),
    Case("light_on_receiver_plane", b_light_on_receiver_plane, note="light in the ground's plane (a boundary: no known answer)"),
    Case("light_below_ground", b_light_below_ground, check=ground_dark, note="light under a single-sided ground"),
    Case("mirrored", b_mirrored, check=same_as_base, note="occluder mirrored by a negative scale"),
    Case("zero_area", b_zero_area, check=same_as_base, note="degenerate triangles"),
    Case("camera_inside", b_camera_inside, note="camera inside a closed box"),
    Case("usdc", b_usdc, check=same_as_base, note="the base as .usdc"),
    Case("no_occluder", b_no_occluder, check=all_lit, note="the base without its occluder: all lit"),
    Case("cutout_8bit", b_cutout_8bit, note="8-bit RGBA cutout texture"),
    Case("cutout_16bit", b_cutout_16bit, check=same_as("cutout_8bit"), note="16-bit grey cutout texture (opacity from r)"),
    Case("cutout_palette", b_cutout_palette, check=same_as("cutout_8bit"), note="palette PNG cutout texture"),
    Case("cutout_1x1", b_cutout_1x1, check=same_as("no_occluder"), note="1x1 transparent texture: no occluder left"),
    Case("cutout_usdz", b_cutout_usdz, check=same_as("cutout_8bit"), silent_hazard=True, note="cutout texture inside a .usdz"),
    Case("cutout_truncated_png", b_cutout_truncated_png, message=("cannot be read",), note="truncated PNG: warned, opaque"),
    Case("zero_width_rect", b_zero_width_rect, message=("zero width",), note="RectLight of width 0"),
    Case("inverted_clip", b_inverted_clip, message=("clippingRange",), note="camera clipping range inverted"),
    Case("missing_sublayer", b_missing_sublayer, message=("not_there.usda",), note="a sublayer that is not there"),
    Case("missing_reference", b_missing_reference, message=("no_such_asset.usda",), note="a reference that is not there"),
    Case("rect_nan_width", b_rect_nan_width, "error", ("/World/Light", "inputs:width"), silent_hazard=True),
    Case("rect_inf_width", b_rect_inf_width, "error", ("/World/Light", "inputs:width"), silent_hazard=True),
    Case("sphere_nan_radius", b_sphere_nan_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("disk_inf_radius", b_disk_inf_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("disk_negative_radius", b_disk_negative_radius, "error", ("/World/Light", "inputs:radius"), silent_hazard=True),
    Case("exposure_huge", b_exposure_huge, "error", ("/World/Light", "exposure"), silent_hazard=True, note="exposure 1e6: 2^exposure overflows a float"),
    Case("nan_transform", b_nan_transform, "error", ("/World/Occluder", "transform"), silent_hazard=True),
    Case("inf_transform", b_inf_transform, "error", ("/World/Occluder",), silent_hazard=True),
    Case("negative_count", b_negative_count, "error", ("/World/Occluder", "faceVertexCounts"), silent_hazard=True),
    Case("count_5_minus_2", b_count_5_minus_2, "error", ("/World/Occluder", "faceVertexCounts"), silent_hazard=True,
         note="face counts 5 and -2: their sum matches the 3 indices"),
    Case("broken_syntax", b_broken_syntax, "error", ("broken_syntax.usda:5:3", "parse error")),
    Case("empty", b_empty, "error", ("no shadow-casting light",)),
    Case("dome_only", b_dome_only, check=sky_over_square, silent_hazard=True,
         note="a uniform DomeLight alone: techniques of the sky measured against the square's closed form, the others decline it"),
    # -- mesh topology and time samples (holeIndices, concave faces, samples without a time range)
    Case("hole_face", b_hole_face, check=all_lit, silent_hazard=True, note="the occluder's only face is a hole (holeIndices): nothing casts"),
    Case("concave_pentagon_split", b_concave_pentagon_split, note="a concave pentagon occluder authored as the three triangles that split it"),
    Case("concave_pentagon", b_concave_pentagon, check=same_as("concave_pentagon_split"), silent_hazard=True,
         note="the same pentagon as one face (its first corner does not see all of it: not a fan)"),
    Case("time_samples_only", b_time_samples_only, message=("loaded at time code 12",), check=same_as_base, base="base_dynamic",
         silent_hazard=True, note="light and occluder translates only time-sampled, no time range: the earliest sample"),
    # precision
    Case("far_origin_xy", b_far_origin_xy, check=close_to("base", 0.005), silent_hazard=True,
         note="the base 1e6 from the origin in x and y"),
    Case("far_origin_z", b_far_origin_z, check=close_to("base", 0.005), silent_hazard=True, note="the base 1e6 up in z"),
    Case("tiny_scene", b_tiny_scene, check=close_to("base", 0.005), silent_hazard=True, note="the base scaled by 1e-10"),
    Case("tiny_cutout", b_tiny_cutout, check=close_to("cutout_8bit", 0.005), silent_hazard=True,
         note="cutout_8bit scaled by 1e-10 (the step past a cutout's hole is relative)"),
    Case("far_light_1e4", b_far_light_1e4, check=close_to("far_light_100", 0.006), silent_hazard=True,
         note="a 0.53° sphere light 1e4 up: the shadow it casts from 100 up"),
    Case("room_ceiling", b_room_ceiling, check=all_dark, silent_hazard=True,
         note="camera inside a closed double-sided room, the lamp half a unit above its ceiling"),
    Case("sun_far_wall", b_sun_far_wall, check=sun_wall_penumbra(8.0), silent_hazard=True,
         note="an 8-degree sun partly blocked by a wall 100 away, outside the receivers' window: a penumbra over the whole ground"),
    Case("sun_huge_far_wall", b_sun_huge_far_wall, check=sun_wall_penumbra(1e4), silent_hazard=True,
         note="the same wall 2e4 wide: its corners far outside the region where a caster can shadow a receiver"),
    # texture networks: the UsdPreviewSurface nodes between a cutout's texture and its mesh
    Case("cutout_clamp", b_cutout_clamp, note="8-bit cutout texture, wrapS = wrapT = clamp"),
    Case("cutout_varname_uv", b_cutout_varname_uv, check=same_as("cutout_8bit"), silent_hazard=True,
         note="texture coordinates in primvar uv, read by varname (no st)"),
    Case("cutout_transform2d", b_cutout_transform2d, check=same_as("cutout_8bit"), silent_hazard=True,
         note="UsdTransform2d (scale 0.5) onto the lower-left quarter of a 16x16 texture"),
    Case("cutout_scale_bias", b_cutout_scale_bias, check=same_as("cutout_clamp"), silent_hazard=True,
         note="inverted texture read with scale -1, bias 1"),
    Case("cutout_udim", b_cutout_udim, check=same_as("cutout_clamp"), silent_hazard=True, note="UDIM texture, st in tile 1002"),
    Case("cutout_exr", b_cutout_exr, check=same_as("cutout_8bit"), silent_hazard=True, note="OpenEXR cutout texture"),
    # light side and shape
    Case("light_facing_away", b_light_facing_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light turned 180 degrees about X: it emits up, away from everything"),
    Case("light_scaled_away", b_light_scaled_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light scaled (1, 1, -1): its -Z turned up"),
    Case("light_inverted", b_light_inverted, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="the base's rect light scaled (-1, -1, -1): its -Z turned up"),
    Case("disk_facing_away", b_disk_facing_away, check=all_dark, message=("behind its emitting plane",), silent_hazard=True,
         note="a DiskLight in the base's light's place, turned 180 degrees about Y"),
]
BASES = {"base": b_base, "base_sun": b_base_sun, "base_dynamic": b_base_dynamic, "far_light_100": b_far_light_100}
CASES += SEQUENCE_CASES + GAP_CASES + LIGHT_CASES + RECEIVER_CASES + MATERIAL_CASES + SHAPING_CASES
for _bases in (SEQUENCE_BASES, GAP_BASES, LIGHT_BASES, RECEIVER_BASES, MATERIAL_BASES, SHAPING_BASES):
    BASES.update(_bases)


def judge(case: Case, technique: str, res: Result, frame_of: Callable[[str], dict | None]) -> list[str]:
    """What is wrong with a result (empty: as expected); ``frame_of(stage name)`` gives the channels
    of another stage rendered with the same technique (the base, or the one a case must equal)."""
    problems = []
    if case.expect == "error":
        if res.rc != 2:
            problems.append(f"exit {res.rc}, want 2")
        if "\n" in res.error or not res.error:
            problems.append("no one-line error")
        problems += [f"error line lacks {m!r}: {res.error}" for m in case.message if m not in res.error]
        if "Traceback" in res.stderr:
            problems.append("traceback")
        return problems
    if res.rc != 0:
        return [f"exit {res.rc}: {res.error or res.stderr.strip()[-300:]}"]
    if res.stats.get("nonfinite"):
        problems.append(f"non-finite values: {res.stats['nonfinite']}")
    warned = all(any(m in w for w in res.warnings) for m in case.message)
    if not case.warn_instead and not warned:
        problems += [f"no warning with {m!r}" for m in case.message if not any(m in w for w in res.warnings)]
    if "Traceback" in res.stderr or "Warning: in " in res.stderr:
        problems.append("raw USD or Python diagnostics on stderr")
    if case.check is not None:
        wants = getattr(case.check, "wants", None)
        if wants is not None:
            other = frame_of(wants)
            msg = case.check(res.channels, None, technique, {wants: other}) if other is not None else f"no frame of {wants}"
        else:
            msg = case.check(res.channels, frame_of(case.base), technique)
        if msg and not (case.warn_instead and warned):
            problems.append(msg + (f" and no warning with {case.message}" if case.warn_instead else ""))
    return problems


# known defects the corpus shows: (case, technique) -> what the defect is and where it lies
KNOWN: dict[tuple[str, str], str] = {
    ("wall_under_wide_light", "ssm"): ("its backprojection misses part of the shelf over a receiver at grazing incidence to the light: "
                                       "V 0.50 below the shelf at 48 x 36 (0.01 at 96 x 72, 0.19 at 160 x 120; 0.24 to 0.36 with the "
                                       "light wholly in front of the wall), where the truth is 0"),
    **{("huge_far_triangle_sun", t): ("a distant light's clipmap levels and depth range are sized by the scene's bounds: a triangle with "
                                      "corners at +-1e7 stretches them (texels and float32 depths far coarser than the 10-unit stage), "
                                      "the shadow is lost (V differs from the base by up to 1 on every ground pixel), with no warning")
       for t in ("vsmap", "smrt")},
    **{("plate_on_ground", t): ("its depth and receiver-plane biases are wider than the plate's 1e-4 gap at its default texels: one "
                                "depth per texel cannot tell the plate from the ground under it, which comes out lit (V 1.000 under "
                                "the plate, the truth 0), with no warning; the gap at which it holds is not measured")
       for t in ("vsmap", "smrt")},
    ("sun_far_wall", "smrt"): ("the penumbra cap: its rays stay within max_ray_angle (0.03 rad) of the sun's centre, and the part of the "
                               "8-degree sun the wall blocks lies beyond it (mean V 0.991 on the ground, the exact 0.837)"),
    ("sun_huge_far_wall", "smrt"): ("the penumbra cap: its rays stay within max_ray_angle (0.03 rad) of the sun's centre, and the part of "
                                    "the 8-degree sun the wall blocks lies beyond it (mean V 0.969 on the ground, the exact 0.800)"),
}
KNOWN.update(GAP_KNOWN)


@contextlib.contextmanager
def _quiet_usd():
    """Keep USD's own warnings (a builder authoring a missing sublayer) off stderr."""
    from pxr import UsdUtils

    d = UsdUtils.CoalescingDiagnosticDelegate()
    try:
        yield
    finally:
        d.TakeUncoalescedDiagnostics()
        del d


def write_stage(name: str, folder: str) -> str:
    """Write the stage of case (or base) ``name`` into ``folder``; its path. USD's own diagnostics
    while building (a missing sublayer authored on purpose) are kept off stderr."""
    build = BASES.get(name) or next(c.build for c in CASES if c.name == name)
    with _quiet_usd():
        return build(folder)
