"""The command line end to end: EXR channels, stats keys, clean errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT, scene_path, wsoft_cli

from wsoft.io import read_exr
from wsoft.techniques import TECHNIQUES


def run(*args, check=True):
    p = wsoft_cli(*args, cwd=ROOT)
    if check and p.returncode != 0:
        raise AssertionError(f"exit {p.returncode}\n{p.stdout}\n{p.stderr}")
    return p


STATS_KEYS = {"technique", "params", "device", "scene", "timings_ms", "memory_bytes", "counters", "passes"}


def test_render_reference_multi_light(tmp_path):
    exr, stats, png = tmp_path / "r.exr", tmp_path / "r.json", tmp_path / "r.png"
    run("render", scene_path("multi_light.usda"), "-t", "reference", "--set", "samples=4", "--width", "40", "--height", "30",
        "--device", "cpu", "--out", str(exr), "--stats", str(stats), "--png", str(png))
    ch = read_exr(str(exr))
    expected = {"V", "V_stderr", "P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "Z", "A", "R", "G", "B"}
    expected |= {f"V.{n}" for n in ("Rect", "Disk", "Sphere", "Sun")}
    assert expected <= set(ch)
    for name, a in ch.items():
        assert a.dtype == np.float32 and a.shape == (30, 40) and np.all(np.isfinite(a)), name
    assert np.array_equal(ch["V"], ch["V.Rect"])
    s = json.loads(stats.read_text())
    assert STATS_KEYS <= set(s)
    assert s["params"] == {"samples": 4, "seed": 0, "jitter": True, "casters": "all", "traversal": "auto"}
    assert "total" in s["timings_ms"] and s["passes"][0] == "upload_scene"
    assert png.stat().st_size > 0


def test_render_hard_with_set_and_light(tmp_path):
    exr, stats = tmp_path / "h.exr", tmp_path / "h.json"
    p = run("render", scene_path("multi_light.usda"), "-t", "hard", "--set", "shadow_map_size=512", "--set", "bias=0.0002",
            "--light", "Sun", "--width", "32", "--height", "24", "--device", "cpu", "--out", str(exr), "--stats", str(stats))
    s = json.loads(stats.read_text())
    assert s["params"]["shadow_map_size"] == 512 and s["params"]["bias"] == 0.0002 and s["params"]["slope_bias"] == 1.5
    assert s["light"] == "/World/Lights/Sun"
    assert "hard[Sun]" in p.stdout
    assert "V_stderr" not in read_exr(str(exr))


def test_plan_and_techniques_json():
    p = json.loads(run("plan", scene_path("cutout.usda"), "--json").stdout)
    assert p["cutout_materials"][0]["triangles"] == 2
    t = json.loads(run("techniques", "--json").stdout)
    names = {x["name"] for x in t}
    assert {"hard", "reference"} <= names
    hard = next(x for x in t if x["name"] == "hard")
    assert {q["name"] for q in hard["parameters"]} == {"view", "cube", "shadow_map_size", "bias", "slope_bias", "receiver_bias", "plane_slope_bias", "conservative", "map_texels", "omni"}


def _bad_mesh(tmp_path):
    f = tmp_path / "bad.usda"
    f.write_text('#usda 1.0\ndef Mesh "Tri"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(0,1,0)]\n'
                 '    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 9]\n}\n')
    return f


@pytest.mark.parametrize(
    "case,needle",
    [
        ("missing", "file not found"),
        ("broken", "cannot open USD stage"),
        ("face", "/Tri: faceVertexIndices[2] = 9 is out of range"),
        ("nolight", "no shadow-casting light"),
        ("technique", "unknown technique 'nope'; techniques: " + ", ".join(sorted(TECHNIQUES))),
        ("param", "technique 'hard' has no parameter samples"),
        ("value", "shadow_map_size='abc' is not a valid int"),
        ("camera", "no camera '/World/Nope'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, case, needle):
    out = str(tmp_path / "o.exr")
    box = scene_path("box_plane.usda")
    args = {
        "missing": [str(tmp_path / "none.usda"), "-t", "hard"],
        "broken": [str(tmp_path / "broken.usda"), "-t", "hard"],
        "face": [str(_bad_mesh(tmp_path)), "-t", "hard"],
        "nolight": [str(tmp_path / "nolight.usda"), "-t", "hard"],
        "technique": [box, "-t", "nope"],
        "param": [box, "-t", "hard", "--set", "samples=3"],
        "value": [box, "-t", "hard", "--set", "shadow_map_size=abc"],
        "camera": [box, "-t", "hard", "--camera", "/World/Nope"],
    }[case]
    (tmp_path / "broken.usda").write_text("#usda 1.0\n(((\n")
    (tmp_path / "nolight.usda").write_text('#usda 1.0\ndef Mesh "Tri"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(0,1,0)]\n'
                                          '    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n}\n')
    p = run("render", *args, "--width", "8", "--height", "8", "--device", "cpu", "--out", out, check=False)
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("wsoft: error")]
    assert len(lines) == 1 and needle in lines[0], p.stderr
    if case in ("missing", "broken", "face", "nolight"):
        assert str(tmp_path) in lines[0]  # names the file


def test_unwritable_output_is_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    p = run("render", scene_path("box_plane.usda"), "-t", "hard", "--width", "8", "--height", "8", "--device", "cpu",
            "--out", str(blocker / "sub" / "o.exr"), check=False)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines()[-1].startswith("wsoft: error:")


def test_plan_text():
    out = run("plan", scene_path("multi_light.usda"), "-t", "hard").stdout
    assert "/World/Lights/Dome" in out and "shadow:enable = false" in out
    assert "cutout (perforated) materials: (none)" in out
    assert "hard: upload_scene -> gbuffer -> " in out


def test_compare_several_techniques_in_one_graph(tmp_path):
    out = tmp_path / "cmp"
    p = run("compare", "box_plane", "-t", "pcss", "-t", "hard", "--set", "pcss.filter_samples=16", "--set", "hard.shadow_map_size=512",
            "--samples", "16", "--width", "40", "--height", "30", "--device", "cpu", "--out-dir", str(out))
    md = (out / "box_plane-compare.md").read_text()
    assert "| gbuffer | gbuffer | " in md and "(shared)" in md
    assert "| pcss | Light |" in md and "| hard | Light |" in md  # an error row per technique
    for label in ("pcss", "hard", "reference"):
        s = json.loads((out / f"box_plane-{label}.json").read_text())
        assert s["label"] == label and (out / f"box_plane-{label}.exr").exists()
    assert json.loads((out / "box_plane-pcss.json").read_text())["params"]["filter_samples"] == 16
    assert json.loads((out / "box_plane-hard.json").read_text())["params"]["shadow_map_size"] == 512
    assert "wrote" in p.stdout


def test_compare_set_needs_a_technique_with_several(tmp_path):
    p = run("compare", "box_plane", "-t", "pcss", "-t", "hard", "--set", "bias=0.1", "--width", "8", "--height", "8", "--device", "cpu",
            "--out-dir", str(tmp_path), check=False)
    assert p.returncode == 2 and "write TECHNIQUE.bias=0.1" in p.stderr and "Traceback" not in p.stderr


def test_techniques_markdown_and_ranges():
    md = run("techniques", "--markdown").stdout
    assert md.startswith("| name | what |") and "| `ssm` |" in md
    text = run("techniques").stdout
    assert "shadow_map_size  int    default 1024     texels per side of the light depth map [256..8192]" in text
    assert "quality: filter_samples over 16, 36, 100" in text


def test_bench_with_a_missing_scene_folder_is_one_line(tmp_path):
    p = run("bench", "foundation", "--quick", "--scenes", str(tmp_path / "nope"), "--out-dir", str(tmp_path / "r"), check=False)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "nope" in p.stderr.strip().splitlines()[-1]


def test_out_of_range_value_is_one_line(tmp_path):
    p = run("render", "box_plane", "-t", "pcss", "--set", "bias=nan", "--width", "8", "--height", "8", "--device", "cpu",
            "--out", str(tmp_path / "o.exr"), check=False)
    assert p.returncode == 2 and "bias is NaN" in p.stderr and "Traceback" not in p.stderr


def _main(*args):
    """The CLI in-process: (exit code, stdout, stderr)."""
    from wsoft.cli import run_captured

    return run_captured(args)


def test_output_paths_are_checked_before_rendering(tmp_path):
    base = scene_path("box_plane.usda")
    small = ("--width", "16", "--height", "12", "--device", "cpu")
    rc, _, err = _main("render", base, "-t", "hard", *small, "--out", str(tmp_path))  # a folder
    assert rc == 2 and "is a directory" in err and len(err.strip().splitlines()) == 1
    rc, _, err = _main("render", base, "-t", "hard", *small, "--out", base + "/x.exr")  # under a file
    assert rc == 2 and "is not a directory" in err and "File exists" not in err
    exr = tmp_path / "f.exr"
    rc, _, err = _main("render", base, "-t", "hard", *small, "--out", str(exr), "--stats", base + "/s.json")
    assert rc == 2 and "--stats" in err and "is not a directory" in err
    assert not exr.exists()  # checked before rendering: nothing half-written


def test_unwritable_png_fails_before_the_exr_is_written(tmp_path):
    base = scene_path("box_plane.usda")
    exr = tmp_path / "f.exr"
    rc, _, err = _main("render", base, "-t", "hard", "--width", "16", "--height", "12", "--out", str(exr), "--png", str(tmp_path))
    assert rc == 2 and "--png" in err and not exr.exists()


def test_help_shows_choices_and_defaults():
    rc, out, _ = _main("render", "--help")
    assert rc == 0 and "default: 640" in out and "default: 480" in out
    assert all(t in out for t in ("pcss", "essm", "vssm", "salzman", "reference"))
    rc, out, _ = _main("bench", "--help")
    assert rc == 0 and all(s in out for s in ("foundation", "pareto", "adversarial"))
    rc, out, _ = _main("compare", "--help")
    assert rc == 0 and "-compare.md" in out and "default: out" in out


def test_bad_time_and_bad_technique_are_one_line_errors():
    rc, _, err = _main("render", scene_path("box_plane.usda"), "-t", "hard", "--time", "nan", "--out", "/tmp/wsoft-never.exr")
    assert rc == 2 and "time code nan" in err and len(err.strip().splitlines()) == 1
    rc, _, err = _main("render", scene_path("box_plane.usda"), "-t", "nope", "--out", "/tmp/wsoft-never.exr")
    assert rc == 2 and "unknown technique 'nope'" in err and len(err.strip().splitlines()) == 1


def test_nonfinite_channels_are_counted_and_warned(tmp_path):
    from wsoft.errors import NonFiniteWarning
    from wsoft.io import nonfinite_counts, write_exr

    ch = {"V": np.array([[0.5, np.nan], [np.inf, 1.0]], np.float32), "A": np.ones((2, 2), np.float32)}
    assert nonfinite_counts(ch) == {"V": 2}
    with pytest.warns(NonFiniteWarning, match="V 2"):
        bad = write_exr(str(tmp_path / "n.exr"), ch)
    assert bad == {"V": 2}
    assert read_exr(str(tmp_path / "n.exr"))["V"][0, 1] == 0.0


@pytest.mark.parametrize("key,value", [("bias", "inf"), ("bias", "1e30"), ("slope_bias", "inf")])
def test_parameters_that_erase_shadows_are_refused(key, value):
    rc, _, err = _main("render", scene_path("box_plane.usda"), "-t", "hard", "--set", f"{key}={value}", "--out", "/tmp/wsoft-never.exr")
    assert rc == 2 and key in err
    for tech, kv in (("esm", "bias=inf"), ("vsm", "min_variance=1e30")):
        rc, _, err = _main("render", scene_path("box_plane.usda"), "-t", tech, "--set", kv, "--out", "/tmp/wsoft-never.exr")
        assert rc == 2 and kv.split("=")[0] in err
