"""The known failure cases of the filtered techniques as in-memory stages: the tests pin them and
the ``filtered`` sweep shows them (technique, reference, difference)."""

from __future__ import annotations

from wsoft.stages.builders import (
    add_box,
    add_camera,
    add_mesh,
    add_point_light,
    add_quad,
    add_rect_light,
    add_sun,
    make_stage,
)


def pcss_overlapping_blockers(high: bool = True):
    """Blockers at two depths average to one too near the light: the filter grows into the umbra."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 6)
    add_quad(st, "/World/Low", (0, 0, 0.6), 1.5)  # large, close to the ground: a wide umbra
    if high:
        add_quad(st, "/World/High", (0.2, 0, 3.0), 0.2)  # small, near the light, inside the blocker search
    add_rect_light(st, "/World/L", (0, 0, 4), 1.0, 1.0)
    add_camera(st, "/World/Cam", (0, -5, 0.35), (0, 0, 0), focal=16)  # low, to see the ground under Low
    return st


def vsm_stacked_occluders(upper: bool = True):
    """An upper occluder's edge over a lower one's umbra: the moments' variance lets light bleed in."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 6)
    add_quad(st, "/World/Lower", (0, 0, 0.5), 1.5)
    if upper:
        add_quad(st, "/World/Upper", (-0.8, 0, 2.5), 0.8)  # its edge at x = 0, over Lower's umbra
    add_rect_light(st, "/World/L", (0, 0, 4), 0.3, 0.3)
    add_camera(st, "/World/Cam", (0, -5, 0.3), (0, 0, 0.1), focal=16)  # low: sees under Lower
    return st


def esm_contact():
    """A thin plate just above the ground under a slanted sun: the receiver is only a little
    behind the occluder, so exp(-c (z - d)) stays above 0 and light leaks in."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 4)
    add_box(st, "/World/Plate", (-1.0, -1.0, 0.1), (1.0, 1.0, 0.13))
    add_sun(st, "/World/Sun", 0.5, (0, -45, 0))
    add_camera(st, "/World/Cam", (1, -3, 3), (0.3, 0, 0), focal=18)
    return st


def salzman_receiver_between_casters(lower: bool = True):
    """A shelf between two dynamic casters: near the upper caster's edge the blur averages the two
    casters' depths, the reconstructed depth falls behind the shelf and the shelf escapes."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    shelf = [(-1.5, -0.1, 2.0), (1.5, -0.1, 2.0), (1.5, 0.1, 2.0), (-1.5, 0.1, 2.0)]  # a narrow strip: the ground stays in view
    add_mesh(st, "/World/Shelf", (shelf, [4], [0, 1, 2, 3]), True, minimal=True)
    add_quad(st, "/World/Upper", (0.3, 0, 2.6), 0.6, dynamic=True)
    if lower:
        add_quad(st, "/World/Lower", (0, 0, 0.1), 1.2, dynamic=True)
    add_point_light(st, "/World/L", (0, 0, 4))  # a point light: the umbra reaches the caster's edge
    add_camera(st, "/World/Cam", (-0.45, -0.001, 3.3), (-0.45, 0, 2.0), focal=50)  # at the upper caster's edge
    return st


# name -> (stage builder, technique, its parameters, reference parameters)
FAILURES = {
    "pcss_overlapping_blockers": (pcss_overlapping_blockers, "pcss", {}, {"samples": 256}),
    "vsm_stacked_occluders": (vsm_stacked_occluders, "vsm", {"radius": 4, "bleed_reduction": 0.0}, {"samples": 64}),
    "esm_contact": (esm_contact, "esm", {"c": 20.0}, {"samples": 64}),
    "salzman_receiver_between_casters": (salzman_receiver_between_casters, "salzman", {"radius": 16, "shadow_map_size": 512}, {"samples": 1, "casters": "dynamic"}),
}
