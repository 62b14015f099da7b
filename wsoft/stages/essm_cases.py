"""In-memory stages for ESSM's hard cases: the tests pin them and the ``essm`` sweep shows them."""

from __future__ import annotations

from wsoft.stages.builders import add_box, add_camera, add_quad, add_rect_light, make_stage


def essm_contact_box():
    """A cube standing on the ground under a rect light: the umbra must stay dark up to the
    contact line (the cube's base), where occluder and receiver depths meet."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 6)
    add_box(st, "/World/Cube", (-0.5, -0.5, 0.0), (0.5, 0.5, 1.0))
    add_rect_light(st, "/World/L", (-1.5, 0, 4), 0.8, 0.8)
    add_camera(st, "/World/Cam", (3.5, -3.0, 3.0), (0.8, 0, 0), focal=18)
    return st


def essm_nonplanar(ground: bool = True):
    """A receiver plate between two occluder depths: an occluder above it, and the ground far below
    around it, both inside its filter kernels. The ground's texels make the ESM sum exceed 1
    (a non-planar kernel); clamped, the plate's penumbra comes out lit."""
    st = make_stage()
    if ground:
        add_quad(st, "/World/G", (0, 0, 0), 6)
    add_quad(st, "/World/Plate", (0, 0, 1.0), 0.6)
    add_quad(st, "/World/Occluder", (-0.75, 0, 2.2), 0.5)  # its shadow's edge crosses the plate
    add_rect_light(st, "/World/L", (0, 0, 4), 1.2, 1.2)
    add_camera(st, "/World/Cam", (0, -0.01, 3.3), (0, 0, 1.0), focal=30)
    return st
