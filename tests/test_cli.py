"""The command line end to end: EXR channels, stats keys, clean errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, scene_path

from wsoft.io import read_exr


def run(*args, check=True):
    p = subprocess.run([sys.executable, "-m", "wsoft", *args], capture_output=True, text=True, cwd=ROOT, timeout=600)
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
    assert s["params"] == {"samples": 4, "seed": 0, "jitter": True, "casters": "all"}
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
    assert {q["name"] for q in hard["parameters"]} == {"shadow_map_size", "bias", "slope_bias", "conservative"}


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
        ("technique", "unknown technique 'nope'; techniques: esm, essm, hard, pcf, pcss, reference, salzman, ssm, vsm, vssm"),
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
