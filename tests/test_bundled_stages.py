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
         "wedge_overlap", "ramp_slide", "ramp_static")


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
