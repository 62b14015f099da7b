"""``python -m wsoft.stages.bundled`` writes the committed bundled stages: the scenes built without
random numbers come out with the same layer text as the files in ``usd_scenes/``, their textures
byte for byte."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT, SCENES
from pxr import Sdf

from wsoft.stages.bundled import SCENES as GENERATORS

# no random numbers: the same on every numpy (a Generator's streams may change between versions)
PLAIN = ("box_plane", "contact", "multi_light", "cutout", "penumbra_ramp", "tower", "tunnel_fan", "fence_perforated",
         "wedge_overlap", "ramp_slide", "ramp_static", "room_lamp", "corridor_torch", "walker")


def test_every_bundled_stage_has_a_generator():
    from wsoft import usd_scenes

    assert sorted(GENERATORS) == usd_scenes.names()


def test_plain_stages_regenerate_as_committed(tmp_path):
    r = subprocess.run([sys.executable, "-m", "wsoft.stages.bundled", "--out", str(tmp_path), *PLAIN],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.splitlines()) == len(PLAIN)
    for name in PLAIN:
        (new,) = tmp_path.glob(name + ".usd*")
        old = SCENES + "/" + new.name
        assert Sdf.Layer.OpenAsAnonymous(str(new)).ExportToString() == Sdf.Layer.OpenAsAnonymous(old).ExportToString(), name
    written = sorted(p.name for p in (tmp_path / "textures").iterdir())
    assert written == ["checker_alpha.png", "fence_alpha.png"]
    for png in written:
        assert (tmp_path / "textures" / png).read_bytes() == open(SCENES + "/textures/" + png, "rb").read(), png


def test_unknown_scene_is_refused(capsys):
    from wsoft.stages.bundled import main

    with pytest.raises(SystemExit) as exc:
        main(["--out", "/nonexistent", "no_such_scene"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "unknown scene 'no_such_scene'" in err and "Traceback" not in err


@pytest.mark.parametrize("name", PLAIN)
def test_plain_generators_use_no_random_numbers(name, tmp_path, monkeypatch):
    """The scenes compared above are the ones whose generators never draw a random number."""
    import numpy as np

    def refuse(*a, **k):
        raise AssertionError("random numbers drawn")

    monkeypatch.setattr(np.random, "default_rng", refuse)
    GENERATORS[name](str(tmp_path))


@pytest.mark.parametrize("name", ["room_lamp", "corridor_torch"])
def test_interiors_surround_their_light_and_render_without_nan(name):
    """A light inside a closed room or corridor: receivers the camera sees lie on every side of it
    (below, above, beyond and before it along the camera's view), and ``hard`` and the
    reference render a small frame of it with no NaN, some of it lit and some in shadow."""
    import warnings

    import numpy as np

    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(name)
    (light,) = scene.lights
    assert light.kind_name == "sphere" and len(scene.cameras) == 1
    lo, hi = scene.points.min(axis=0), scene.points.max(axis=0)
    assert np.all(lo < light.position) and np.all(light.position < hi)  # the light is inside the shell
    frames = {}
    for tech, params in (("hard", {"shadow_map_size": 256}), ("reference", {"samples": 8})):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # hard's single frustum leaves receivers beyond it lit, with a warning
            frames[tech] = wsoft.render(scene, tech, width=48, height=36, device="cpu", **params)
    for tech, f in frames.items():
        V = np.asarray(f.V)
        assert V.shape == (36, 48) and not np.isnan(V).any(), tech
    V = np.asarray(frames["reference"].V)
    assert (V > 0.99).mean() > 0.3 and (V < 0.01).mean() > 0.02, name
    # directions from the light to the visible receivers: some below, some above, some behind
    f = frames["reference"]
    P = np.stack([f["P.X"], f["P.Y"], f["P.Z"]], axis=-1)[f["A"] > 0.5]
    d = P - light.position
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert (d[:, 2] < -0.7).any() and (d[:, 2] > 0.7).any(), name
    ahead = d @ -np.asarray(scene.cameras[0].to_world, np.float64)[:3, 2]  # along the camera's view
    assert (ahead > 0.3).mean() > 0.1 and (ahead < -0.3).mean() > 0.1, name  # receivers beyond the light and before it
