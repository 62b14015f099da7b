"""ꟻLIP beside MAE: the shaded image as its PNG shows it, against the reference's, in the metric
pass, ``wsoft.compare``, ``wsoft compare`` and the harness's ground truths."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path, wsoft_cli

from wsoft.metrics.flip import flip_error, ldr_image, magma

H, W = 48, 64


def _image(a: np.ndarray | None = None) -> dict:
    """A shaded image with structure (a ramp and a dark square), covered where ``a`` > 0 (default: everywhere)."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    base = 0.15 + 0.6 * x / W
    base[12:30, 20:40] *= 0.2
    a = np.ones((H, W), np.float32) if a is None else a
    return {"R": base * a, "G": 0.8 * base * a, "B": 0.6 * base * a, "A": a}


def _scaled(img: dict, k: float) -> dict:
    return {c: np.clip(img[c] * k, 0, 1).astype(np.float32) for c in "RGB"} | {"A": img["A"]}


def test_the_reference_against_itself_is_zero():
    ref = _image()
    e, emap = flip_error(ref, {c: v.copy() for c, v in ref.items()})
    assert e == {"flip": 0.0, "flip_covered": 0.0, "flip_nan_pixels": 0}
    assert emap.shape == (H, W) and emap.dtype == np.float32 and not emap.any()


def test_a_brighter_image_scores_above_zero_and_a_more_different_one_more():
    ref = _image()
    a, amap = flip_error(_scaled(ref, 1.25), ref)
    b, _ = flip_error(_scaled(ref, 2.0), ref)
    assert 0.0 < a["flip"] < b["flip"] <= 1.0
    assert (amap > 0).mean() > 0.9  # brighter everywhere: an error nearly everywhere
    # the mean is ꟻLIP's own (float64 over its map)
    import flip_evaluator

    _, mean, _ = flip_evaluator.evaluate(ldr_image(ref), ldr_image(_scaled(ref, 1.25)), "LDR", applyMagma=False)
    assert a["flip"] == pytest.approx(mean, rel=1e-5)


def test_the_covered_mean_ignores_the_background():
    cov = np.zeros((H, W), np.float32)
    cov[:, :24] = 1.0
    ref = _image(cov)
    test = {c: v.copy() for c, v in ref.items()}
    for c in "RGB":
        test[c][:, 48:] = 0.9  # a bright background far (24 pixels) from the covered pixels
    e, emap = flip_error(test, ref)
    assert e["flip"] > 0.05 and emap[:, 48:].min() > 0.1
    assert e["flip_covered"] == 0.0
    # and on a covered difference: the map's mean over A > 0
    test["R"][10:20, 5:15] = 1.0
    e, emap = flip_error(test, ref)
    assert e["flip_covered"] == pytest.approx(emap[:, :24].mean(dtype=np.float64)) and e["flip_covered"] > 0.0
    assert e["flip"] == pytest.approx(emap.mean(dtype=np.float64))


def test_a_nan_is_counted_warned_and_scored_one():
    ref = _image()
    test = {c: v.copy() for c, v in ref.items()}
    test["G"][5, 7] = np.nan
    test["B"][6, 8] = np.inf
    with pytest.warns(RuntimeWarning, match="2 pixels .* not finite"):
        e, emap = flip_error(test, ref)
    assert e["flip_nan_pixels"] == 2 and emap[5, 7] == 1.0 and emap[6, 8] == 1.0
    assert e["flip"] >= 2.0 / (H * W)


def test_the_ldr_image_is_the_png_and_the_colours_are_flips_magma(tmp_path):
    from PIL import Image

    import flip_evaluator
    from wsoft.io import write_png

    ref = _image()
    write_png(str(tmp_path / "r.png"), ref)
    png = np.asarray(Image.open(tmp_path / "r.png"))
    assert np.array_equal(ldr_image(ref) * 255.0, png.astype(np.float32))
    test = _scaled(ref, 1.6)
    _, emap = flip_error(test, ref)
    coloured, _, _ = flip_evaluator.evaluate(ldr_image(ref), ldr_image(test), "LDR")  # applyMagma by default
    mine = magma(emap).astype(np.int16)
    assert np.abs(mine - np.round(np.asarray(coloured).reshape(H, W, 3) * 255).astype(np.int16)).max() <= 1
    assert len(np.unique(mine.reshape(-1, 3), axis=0)) > 10


def test_compare_gives_flip_per_technique_and_zero_for_the_reference_against_itself():
    import wsoft
    from wsoft.metrics import GroundTruth

    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    kw = dict(width=64, height=48, device="cpu")
    fs = wsoft.compare(scene, ["hard", "pcss"], samples=16, **kw)
    for label in ("hard", "pcss"):
        e = fs[label].stats["error"]
        assert 0.0 < e["flip"] < 0.2 and 0.0 < e["flip_covered"] and e["flip_nan_pixels"] == 0
        assert fs[label].error_maps["flip"].shape == (48, 64)
        assert e["flip"] == pytest.approx(fs[label].error_maps["flip"].mean(dtype=np.float64))
    assert "flip" not in fs["reference"].error_maps
    assert sum(p.startswith("flip[") for p in fs.stats["passes"]) == 2  # one ꟻLIP pass per technique

    ref = wsoft.render(scene, "reference", samples=4, **kw)
    label = ref.stats["light_labels"][0]
    truth = GroundTruth({label: {"V": ref.V, "V_stderr": ref["V_stderr"], "A": ref["A"]}}, 4, shaded={c: ref[c] for c in "RGB"})
    same = wsoft.compare(scene, [("reference", {"samples": 4})], ground_truth=truth, **kw)["reference"].stats["error"]
    assert same["mae"] == 0.0 and same["flip"] == 0.0 and same["flip_covered"] == 0.0
    # a ground truth without its shaded image: MAE as before, no ꟻLIP
    bare = wsoft.compare(scene, ["hard"], ground_truth=GroundTruth(truth.lights, 4), **kw)["hard"]
    assert "flip" not in bare.stats["error"] and not bare.error_maps and bare.stats["error"]["mae"] > 0.0


def test_every_light_of_a_technique_carries_its_one_image_value():
    import wsoft

    fs = wsoft.compare(wsoft.load_scene(scene_path("multi_light.usda")), ["hard"], samples=4, width=40, height=30, device="cpu")
    errs = fs["hard"].stats["errors"]
    assert len(errs) >= 2 and len({e["flip"] for e in errs.values()}) == 1 and next(iter(errs.values()))["flip"] > 0.0
    assert [p for p in fs.stats["passes"] if p.startswith("flip[")] == ["flip[hard]"]


def test_the_cli_writes_the_flip_map_and_the_column(tmp_path):
    from PIL import Image

    out = tmp_path / "cmp"
    p = wsoft_cli("compare", "box_plane", "-t", "hard", "--samples", "4", "--width", "32", "--height", "24", "--device", "cpu",
                  "--out-dir", str(out))
    assert p.returncode == 0, p.stderr
    png = out / "box_plane-hard-flip.png"
    assert Image.open(png).size == (32, 24) and Image.open(png).mode == "RGB"
    assert not (out / "box_plane-reference-flip.png").exists()
    assert str(out / "box_plane-hard") + ".exr/.png/-V.png/.json/-flip.png" in p.stdout
    md = (out / "box_plane-compare.md").read_text()
    assert "| ꟻLIP | ꟻLIP covered |" in md
    row = next(line for line in md.splitlines() if line.startswith("| hard | Light |"))
    import json

    e = json.loads((out / "box_plane-hard.json").read_text())["error"]
    assert row.endswith(f"| {e['flip']:.4f} | {e['flip_covered']:.4f} |") and e["flip"] > 0.0
    assert "| flip[hard] | metric |" in md


def test_the_harness_ground_truth_carries_the_shaded_image(monkeypatch, tmp_path):
    from wsoft.bench import harness

    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path / "cache"))
    kw = dict(width=32, height=24, light=None)
    ref = harness.reference("box_plane", samples=4, **kw)
    again = harness.reference("box_plane", samples=4, **kw)
    assert again["cached"] and all(np.array_equal(ref[c], again[c]) and ref[c].shape == (24, 32) for c in "RGB")
    truth = harness.ground_truth("box_plane", ref, None)
    assert set(truth.shaded) == set("RGB")
    hard = harness.measure_render("box_plane", "hard", {}, device="cpu", repeats=1, truth=truth, **kw)
    assert hard.stats["error"]["flip"] > 0.0 and "flip" in hard.error_maps
    same = harness.measure_render("box_plane", "reference", {"samples": 4}, device="cpu", repeats=1, truth=truth, **kw)
    assert same.stats["error"]["flip"] == 0.0 and same.stats["error"]["mae"] == 0.0
