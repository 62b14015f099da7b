"""A floor lit at grazing incidence by a point-like light: the acne case of the filtered
techniques. The light hangs a little above a wide floor that runs on under it; the camera looks
along the floor away from the light, so the frame holds receivers from about 64 degrees off the
light's downward axis out to the floor's far edge (beyond 89). Nothing casts a shadow: every
receiver is lit, so every darkened pixel is the technique's own error. The light's view (at most
80 degrees off its axis) sees the far floor near its edge, where one texel spans a long stretch
of floor and the map's depth changes fast across it; the floor's triangles reach under the light
and are clipped close to it, so the rasterizer's float32 1/z interpolation misplaces depths by a
small fraction of a texel there (tests/test_grazing.py)."""

from __future__ import annotations

import math

import numpy as np

from wsoft.stages.builders import add_camera, add_point_light, add_quad, add_sphere_light, make_stage

LIGHT_HEIGHT = 0.25  # the light's centre above the floor
CAMERA = ((0.0, -1.0, 1.2), (0.0, 2.5, 0.0), 10.0)  # eye, target, focal length (mm)


def grazing_floor(point: bool = False, radius: float = 0.01):
    """The floor (half-side 40, at z = 0) under a SphereLight of ``radius`` at height
    :data:`LIGHT_HEIGHT` above the origin, or a true point light (``treatAsPoint``) with
    ``point``."""
    st = make_stage()
    add_quad(st, "/World/Floor", (0, 0, 0), 40)
    if point:
        add_point_light(st, "/World/Light", (0, 0, LIGHT_HEIGHT))
    else:
        add_sphere_light(st, "/World/Light", (0, 0, LIGHT_HEIGHT), radius)
    eye, target, focal = CAMERA
    add_camera(st, "/World/Cam", eye, target, focal=focal)
    return st


def incidence_degrees(points: np.ndarray) -> np.ndarray:
    """Angle (degrees) between the floor's normal and the direction to the light's centre, for
    floor points ``points`` ([..., 3])."""
    d = np.asarray(points, np.float64) - np.array([0.0, 0.0, LIGHT_HEIGHT])
    return np.degrees(np.arccos(np.clip(np.abs(d[..., 2]) / np.maximum(np.linalg.norm(d, axis=-1), 1e-30), 0.0, 1.0)))


def band_radius(degrees: float) -> float:
    """Distance from the point under the light at which the floor's incidence is ``degrees``."""
    return LIGHT_HEIGHT * math.tan(math.radians(degrees))
