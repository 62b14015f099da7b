"""The closed box with a point light at its centre (``wsoft.stages.omni_cases``): every variant loads
as described, and the reference's one-sample answer shows the shadows where the builder says."""

from __future__ import annotations

import numpy as np
import pytest

from wsoft.stages.omni_cases import BOX_HALF, VARIANTS, WALLS, closed_box_point


def _render(path: str, camera: str = "/World/Camera", size: int = 64):
    import wsoft

    f = wsoft.render(path, "reference", width=size, height=size, device="cpu", samples=1, camera=camera)
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], axis=-1)
    return np.asarray(f.V), P, np.asarray(f["A"]) > 0.5


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_variant_loads_with_a_point_light_at_the_centre(variant, tmp_path):
    from wsoft.pipeline import load_stage
    from wsoft.scene.types import LIGHT_POINT

    path = closed_box_point(str(tmp_path), variant)
    assert path.endswith(f"closed_box_point_{variant}.usda")
    scene = load_stage(path)
    (light,) = scene.lights
    assert light.kind == LIGHT_POINT and np.allclose(light.position, 0.0)
    assert {c.path for c in scene.cameras} == {"/World/Camera"} | {"/World/Cameras/" + w for w in WALLS}
    extra = {"walls": 0, "seams": 2, "receiver_at_light": 1}[variant]
    assert len(scene.prims) == 12 + extra
    assert np.abs(scene.points).max() <= BOX_HALF + 1e-6


def test_a_radius_makes_a_sphere_light_and_bad_arguments_are_refused(tmp_path):
    from wsoft.pipeline import load_stage

    (light,) = load_stage(closed_box_point(str(tmp_path), radius=0.1)).lights
    assert light.kind_name == "sphere" and light.radius == pytest.approx(0.1)
    with pytest.raises(ValueError, match="unknown variant 'edges'"):
        closed_box_point(str(tmp_path), "edges")
    with pytest.raises(ValueError, match="radius"):
        closed_box_point(str(tmp_path), radius=-1.0)


def test_each_wall_camera_sees_its_occluders_shadow_on_its_wall(tmp_path):
    path = closed_box_point(str(tmp_path), "walls")
    for name, (axis, sign) in WALLS.items():
        V, P, cov = _render(path, "/World/Cameras/" + name)
        on = cov & (np.abs(P[..., axis] - sign * BOX_HALF) < 1e-3)
        assert on.mean() > 0.3, name
        shadow = on & (V < 0.5)
        assert shadow.sum() > 20, name
        # the shadow is the occluder's doubled about the light: within 0.6 + 2 * 0.3 of the wall's centre
        inplane = np.delete(P[shadow], axis, axis=1)
        assert np.abs(inplane).max() <= 1.2 + 0.05, name


def test_the_seam_occluders_shadows_straddle_the_box_edge_and_corner(tmp_path):
    V, P, cov = _render(closed_box_point(str(tmp_path), "seams"), size=96)
    sh = cov & (V < 0.5)
    on = {w: np.abs(P[..., a] - s * BOX_HALF) < 1e-3 for w, (a, s) in WALLS.items()}
    assert (sh & on["PX"] & (P[..., 1] > 1.5)).sum() > 5 and (sh & on["PY"] & (P[..., 0] > 1.5)).sum() > 5
    corner = np.linalg.norm(P - np.array([-BOX_HALF, BOX_HALF, BOX_HALF]), axis=-1) < 1.0
    assert all((sh & corner & on[w]).sum() > 5 for w in ("NX", "PY", "PZ"))


def test_the_receiver_at_the_light_renders_without_nan(tmp_path):
    V, P, cov = _render(closed_box_point(str(tmp_path), "receiver_at_light"), size=96)
    assert not np.isnan(V).any()
    assert (np.linalg.norm(P[cov], axis=-1) < 0.1).sum() > 20  # pixels on the triangle around the light
