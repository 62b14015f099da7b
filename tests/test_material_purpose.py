"""Material bindings resolve for a material purpose (``load_scene(material_purpose=...)``): ``full``
by default, as a renderer of final frames does, ``preview`` on request; a prim with no binding of
that purpose takes its all-purpose one (``UsdShade.MaterialBindingAPI.ComputeBoundMaterial``)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage

import wsoft
from wsoft.errors import ParameterError
from wsoft.stages.adversarial.materials import opacity_material


def _stage(purposes: dict[str, float]):
    """A ground, a card above it under a rect light, the card bound for each purpose in
    ``purposes`` ("" all-purpose, "full", "preview") to a material of that opacity."""
    from pxr import UsdShade

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_quad(st, "/World/Card", (0, 0, 1), 1)
    add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(st, "/World/Cam", (0, -4, 4), (0, 0, 0))
    binding = UsdShade.MaterialBindingAPI.Apply(st.GetPrimAtPath("/World/Card"))
    for purpose, opacity in purposes.items():
        binding.Bind(opacity_material(st, f"/World/Looks/M_{purpose or 'all'}", opacity), materialPurpose=purpose)
    return st


def _card_material(scene):
    tri = np.flatnonzero(scene.tri_prim == scene.prims.index("/World/Card"))
    return scene.materials[int(scene.tri_material[tri[0]])]


def _cutout(scene) -> bool:
    return _card_material(scene).is_cutout


def test_full_purpose_binding_is_used_by_default():
    st = _stage({"": 1.0, "full": 0.0})
    assert _cutout(wsoft.load_scene(st))
    assert wsoft.load_scene(st).material_purpose == "full"
    assert not _cutout(wsoft.load_scene(st, material_purpose="preview"))  # no preview binding: the all-purpose one


def test_preview_purpose_binding_on_request():
    st = _stage({"": 1.0, "full": 1.0, "preview": 0.0})
    assert not _cutout(wsoft.load_scene(st))
    assert _cutout(wsoft.load_scene(st, material_purpose="preview"))


def test_only_all_purpose_binding_serves_both():
    st = _stage({"": 0.0})
    assert _cutout(wsoft.load_scene(st)) and _cutout(wsoft.load_scene(st, material_purpose="preview"))


def test_unknown_material_purpose_is_an_error():
    with pytest.raises(ParameterError, match="material_purpose 'final' is not one of full, preview"):
        wsoft.load_scene(_stage({"": 1.0}), material_purpose="final")


def test_full_purpose_cutout_casts_nothing(device):
    """The card, cut out for the full purpose only, casts nothing; the preview look casts its shadow."""
    st = _stage({"": 1.0, "full": 0.0})
    full = wsoft.render(wsoft.load_scene(st), [("reference", {"samples": 16}), "pcss"], width=48, height=36, device=device)
    preview_scene = wsoft.load_scene(st, material_purpose="preview")
    preview = wsoft.render(preview_scene, [("reference", {"samples": 16}), "pcss"], width=48, height=36, device=device)
    for k in ("reference", "pcss"):
        cov = full[k]["A"] > 0
        assert cov.sum() > 500 and full[k].V[cov].min() == 1.0, k
        assert preview[k].V[cov].min() < 0.1, k
    # a load again with other render settings keeps the purpose
    from wsoft.pipeline.loading import with_render_settings

    assert with_render_settings(preview_scene, None).material_purpose == "preview"


def test_the_command_line_chooses_the_purpose(tmp_path):
    """``--material-purpose preview`` draws the preview look; the default, full, the final one; a
    sequence (``--frames``) keeps the purpose in every frame."""
    from wsoft.cli import run_captured
    from wsoft.io import read_exr

    st = _stage({"": 1.0, "full": 0.0})
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(2)
    path = str(tmp_path / "card.usda")
    st.GetRootLayer().Export(path)
    mean = {}
    for purpose in ("full", "preview"):
        out = str(tmp_path / f"{purpose}.exr")
        rc, _, err = run_captured(["render", path, "-t", "hard", "--width", "32", "--height", "24", "--device", "cpu",
                                   "--material-purpose", purpose, "--out", out])
        assert rc == 0, err
        mean[purpose] = float(read_exr(out)["V"].mean())
        seq = str(tmp_path / f"{purpose}-seq.exr")
        rc, _, err = run_captured(["render", path, "-t", "hard", "--width", "32", "--height", "24", "--device", "cpu",
                                   "--material-purpose", purpose, "--frames", "1:2", "--out", seq])
        assert rc == 0, err
        assert float(read_exr(str(tmp_path / f"{purpose}-seq.0002.exr"))["V"].mean()) == mean[purpose]
    assert mean["full"] > mean["preview"]  # the full purpose's cut-out card casts no shadow
    rc, _, err = run_captured(["render", path, "--material-purpose", "final"])
    assert rc == 2 and "--material-purpose" in err
