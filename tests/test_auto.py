"""``--technique auto``: the model file (version checked), the chooser (deterministic; a budget no
candidate fits warns and renders the cheapest), the features against what a render measures, a
plugin technique joining once rows for it exist, and the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import scene_path, wsoft_cli
from test_plugins import site  # noqa: F401  (the README's plugin, installed on a temporary path)

import wsoft
from wsoft.auto.choose import choose, pick
from wsoft.auto.features import FEATURES, light_features
from wsoft.auto.model import VERSION, Model, fit, load_model, model_path, setting_key, training_frames
from wsoft.errors import ParameterError

W, H = 64, 48


@pytest.fixture(scope="module")
def box():
    return wsoft.load_scene(scene_path("box_plane.usda"))


def test_the_packaged_model_loads_with_its_version_and_device_kind():
    m = Model.load(model_path("cpu"))
    assert m.data["version"] == VERSION and m.device_kind == "cpu"
    assert m.method["time"] in ("loglinear", "nearest") and m.method["error"] in ("loglinear", "nearest")
    techniques = {s["technique"] for s in m.settings().values()}
    assert {"hard", "pcss", "reference"} <= techniques and len(m.settings()) > 50


def test_a_wrong_version_is_a_one_line_error(tmp_path, box):
    data = json.loads(model_path("cpu").read_text())
    data["version"] = VERSION + 1
    bad = tmp_path / "old.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(ParameterError, match=r"version .*this wsoft reads version") as e:
        Model.load(bad)
    assert "\n" not in str(e.value)
    r = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "auto", "--budget-ms", "50", "--auto-model", str(bad),
                  "--width", str(W), "--height", str(H), "--out", str(tmp_path / "a.exr"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "version" in r.stderr
    assert not (tmp_path / "a.exr").exists()


def test_a_device_kind_without_a_model_uses_the_cpu_model_scaled_by_a_measured_calibration(monkeypatch):
    from wsoft.auto import calibrate

    m, note = load_model(device="cuda:0")
    assert m.device_kind == "cpu" and "no auto model for device kind 'cuda'" in note and "quick calibration" in note
    monkeypatch.setattr(calibrate, "QUICK_SIZE", (48, 36))
    monkeypatch.setattr(calibrate, "_SCALES", {})
    scale = calibrate.quick_scale(m, "cpu")  # measured here on the CPU: render time over the model's prediction
    assert 0.01 < scale < 100.0 and calibrate._SCALES  # measured once, then reused
    assert m.scaled(scale).predict(light_features_stub(), 'hard{"shadow_map_size": 1024}')[0] == pytest.approx(
        scale * m.predict(light_features_stub(), 'hard{"shadow_map_size": 1024}')[0])


def light_features_stub() -> dict:
    return {"triangles": 4.0, "triangles_in_view": 4.0, "instances": 0.0, "cutout_triangles": 0.0, "pixels": 3072.0, "covered_pixels": 2800.0,
            "light_size": 0.7, "light_distance": 3.0, "shadowed_fraction": 0.02, "penumbra_px": 3.0, "depth_ratio": 1.5}


def test_pick_is_deterministic_and_breaks_ties_by_name():
    preds = {"b": (10.0, 0.1), "a": (10.0, 0.1), "c": (5.0, 0.3), "d": (50.0, 0.01)}
    assert pick(preds, budget_ms=20) == ("a", "b", "")
    assert pick(preds, target_error=0.2)[0] == "a"
    assert pick(preds, target_error=0.05)[0] == "d"
    choice, _, warning = pick(preds, budget_ms=1.0)
    assert choice == "c" and "4.0 ms (400%) over it" in warning
    with pytest.raises(ParameterError):
        pick(preds, budget_ms=10, target_error=0.1)


def test_the_choice_is_deterministic_for_a_model_and_a_stage(box):
    m, _ = load_model()
    a = choose(box, box.lights[0], budget_ms=30, model=m, width=W, height=H).record()
    b = choose(box, box.lights[0], budget_ms=30, model=m, width=W, height=H).record()
    assert a == b and a["choice"] != a["runner_up"]
    assert a["choice"]["ms_bound"] <= 30 and not a["warning"]
    fitting = [c for c in a["candidates"] if c["ms_bound"] <= 30]
    assert a["choice"]["predicted_error"] == min(c["predicted_error"] for c in fitting)


def test_a_budget_below_every_candidate_warns_and_renders_the_cheapest(box):
    f = wsoft.render(box, "auto", budget_ms=0.01, width=W, height=H, device="cpu")
    rec = f.stats["counters"]["techniques"]["auto"]["Light"]["auto"]
    cheapest = min(rec["candidates"], key=lambda c: (c["ms_bound"], c["setting"]))
    assert rec["choice"]["setting"] == cheapest["setting"]
    assert "below every candidate" in rec["warning"] and "over it" in rec["warning"]
    assert any("below every candidate" in w for w in f.stats["warnings"])
    assert np.isfinite(f.V).all() and (f.V < 0.5).any()  # the cheapest setting rendered the shadow
    assert f.stats["technique"] == "auto" and any(p.endswith("[auto:Light]") for p in f.stats["passes"])


def test_features_match_what_the_render_measures(box):
    f = light_features(box, box.lights[0], width=W, height=H)
    assert set(f) == set(FEATURES)
    fr = wsoft.render(box, "hard", width=W, height=H, device="cpu", shadow_map_size=256)
    assert f["triangles"] == fr.stats["counters"]["frame"]["triangles"] == box.total_triangles
    assert f["pixels"] == W * H
    covered = float((fr["A"] > 0).sum())
    assert 0.5 * W * H < covered and abs(f["covered_pixels"] - covered) <= 0.03 * W * H
    # the shadowed fraction of the probe against the hard shadow's (the light's centre) on the same frame
    shadowed = float(((fr.V < 0.5) & (fr["A"] > 0)).sum()) / covered
    assert shadowed > 0.005 and abs(f["shadowed_fraction"] - shadowed) < 0.5 * shadowed + 0.01
    # box_plane: a square light of side 1 (extent = its half-diagonal) and a penumbra several pixels wide
    assert f["light_size"] == pytest.approx(box.lights[0].extent()) and f["penumbra_px"] > 1.0


def _rows_with(technique: str, params: dict, frames: list[dict]) -> list[dict]:
    """The packaged model's training rows, reduced to two settings and one added, ``technique``'s."""
    out = []
    for i, f in enumerate(frames):
        entries = [{"technique": "hard", "params": {"shadow_map_size": 1024}, "frame_ms": 50.0 + i, "error": {"mae_penumbra": 0.2, "mae": 0.1, "penumbra_pixels": 10}},
                   {"technique": technique, "params": params, "frame_ms": 20.0 + i, "error": {"mae_penumbra": 0.01, "mae": 0.01, "penumbra_pixels": 10}}]
        out.append({"scene": f["scene"], "light": f["light"], "entries": entries})
    return out


def test_a_plugin_technique_becomes_a_candidate_once_rows_for_it_exist(site, box):  # noqa: F811
    m, _ = load_model()
    feats = [{"scene": f["scene"], "light": f["light"], "features": _features_of(m, f)} for f in m.data["frames"]]
    assert not any(s["technique"] == "tent_pcf" for s in m.settings().values())
    rec = choose(box, box.lights[0], target_error=0.05, model=m, width=W, height=H).record()
    assert all(c["technique"] != "tent_pcf" for c in rec["candidates"])
    frames = training_frames(_rows_with("tent_pcf", {"radius": 1}, feats), feats)
    m2 = fit(frames)
    assert setting_key("tent_pcf", {"radius": 1}) in m2.settings()
    rec = choose(box, box.lights[0], target_error=0.05, model=m2, width=W, height=H).record()
    assert {c["technique"] for c in rec["candidates"]} == {"hard", "tent_pcf"}
    assert rec["choice"]["technique"] == "tent_pcf"  # faster and more accurate in every row
    f = wsoft.render(box, "auto", target_error=0.05, width=W, height=H, device="cpu", model=str(_saved(m2, site)))
    assert f.stats["counters"]["techniques"]["auto"]["Light"]["auto"]["choice"]["technique"] == "tent_pcf"
    assert (f.V < 0.5).any()


def _features_of(model, frame: dict) -> dict:
    """Stand-in features for a training frame of the packaged model (its standardised values mapped back)."""
    return {"triangles": 1000.0, "triangles_in_view": 1000.0, "instances": 0.0, "cutout_triangles": 0.0, "pixels": 307200.0,
            "covered_pixels": 200000.0 + 1000.0 * len(frame["light"]), "light_size": 0.5, "light_distance": 5.0,
            "shadowed_fraction": 0.1, "penumbra_px": 10.0 + len(frame["scene"]), "depth_ratio": 2.0}


def _saved(model, folder):
    path = folder / "with_plugin.json"
    model.save(path)
    return path


def test_the_command_line_plans_and_renders_auto(tmp_path):
    r = wsoft_cli("plan", scene_path("box_plane.usda"), "-t", "auto", "--target-error", "0.05")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    head = next(l for l in lines if l.startswith("auto (target error 0.05): /World/Light:") or l.startswith("auto (target error 0.05): Light:"))
    assert "runner-up" in head and "candidates" in head
    assert any(l.strip().startswith("features: triangles 4,") for l in lines)
    assert sum(l.endswith("<- choice") for l in lines) == 1 and sum(l.endswith("<- runner-up") for l in lines) == 1
    out = tmp_path / "a.exr"
    r = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "auto", "--budget-ms", "40", "--width", str(W), "--height", str(H),
                  "--out", str(out), "--stats", str(tmp_path / "a.json"))
    assert r.returncode == 0, r.stderr
    assert out.exists() and "auto (budget 40 ms): Light:" in r.stdout
    st = json.loads((tmp_path / "a.json").read_text())
    assert st["counters"]["techniques"]["auto"]["Light"]["auto"]["goal"] == {"budget_ms": 40.0}
    for bad in (["-t", "hard", "--budget-ms", "40"], ["-t", "auto"], ["-t", "auto", "--budget-ms", "40", "--target-error", "0.1"]):
        r = wsoft_cli("render", scene_path("box_plane.usda"), *bad, "--out", str(tmp_path / "b.exr"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (bad, r.stderr)


def test_calibrate_quick_writes_a_scaled_model_and_bad_arguments_are_one_line(tmp_path, monkeypatch):
    from wsoft.auto import calibrate

    monkeypatch.setattr(calibrate, "QUICK_SIZE", (48, 36))
    out = tmp_path / "quick.json"
    r = wsoft_cli("calibrate", "--quick", "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = Model.load(out)
    assert m.scale > 0 and m.scale != 1.0 and m.data["source"]["quick_calibration"]["size"] == [48, 36]
    assert f"times scaled by {m.scale:.3g}" in r.stdout
    for bad in ([], ["--rows", str(tmp_path / "none.jsonl")], ["--quick", "--rows", str(out)]):
        r = wsoft_cli("calibrate", *bad)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (bad, r.stderr)


# -- ꟻLIP and flicker targets -------------------------------------------------------------------


def test_a_flip_target_picks_the_fastest_setting_whose_flip_bound_reaches_it(box):
    m, _ = load_model()
    assert m.method["flip"] in ("loglinear", "nearest") and m.settings("flip")
    rec = choose(box, box.lights[0], target_flip=0.01, model=m, width=W, height=H).record()
    assert rec["goal"] == {"target_flip": 0.01} and not rec["warning"]
    reach = [c for c in rec["candidates"] if c["flip_bound"] <= 0.01]
    assert 0 < len(reach) < len(rec["candidates"])  # the target splits the candidates
    assert rec["choice"]["ms_bound"] == min(c["ms_bound"] for c in reach)
    assert all(c["predicted_flip"] is not None and c["predicted_error"] is not None for c in rec["candidates"])


def test_a_flicker_target_has_only_settings_with_flicker_rows_as_candidates_and_says_which_are_not(box):
    m, _ = load_model()
    fm = m.flicker
    assert fm is not None and fm.quantities == ("time", "flicker") and len(fm.data["frames"]) >= 2
    assert any('"view": "stable"' in k for k in fm.settings())  # temporal's own settings, not the pareto ones
    # the same model with pcss's flicker rows removed: pcss is no candidate, and the record says why
    data = json.loads(json.dumps(m.data))
    data["flicker"]["settings"] = {k: s for k, s in data["flicker"]["settings"].items() if s["technique"] != "pcss"}
    rec = choose(box, box.lights[0], target_flicker=0.003, model=Model(data), width=W, height=H).record()
    assert rec["goal"] == {"target_flicker": 0.003}
    assert "no flicker rows" in rec["not_candidates"]["pcss"]
    assert all(c["technique"] != "pcss" and c["predicted_flicker"] is not None for c in rec["candidates"])
    ok = [c for c in rec["candidates"] if c["flicker_bound"] <= 0.003]
    assert ok and rec["choice"]["ms_bound"] == min(c["ms_bound"] for c in ok)
    # a model without a flicker model refuses a flicker target in one line
    data.pop("flicker")
    with pytest.raises(ParameterError, match="no flicker model") as e:
        choose(box, box.lights[0], target_flicker=0.003, model=Model(data), width=W, height=H)
    assert "\n" not in str(e.value)


def test_flip_and_flicker_targets_render_and_plan_and_bad_goals_are_one_line_errors(tmp_path, box):
    f = wsoft.render(box, "auto", target_flicker=0.01, width=W, height=H, device="cpu")
    rec = f.stats["counters"]["techniques"]["auto"]["Light"]["auto"]
    assert rec["goal"] == {"target_flicker": 0.01} and rec["choice"]["predicted_flicker"] <= rec["choice"]["flicker_bound"]
    assert "flicker model" in rec["model"]["predicts"] and (f.V < 0.5).any()
    r = wsoft_cli("plan", scene_path("box_plane.usda"), "-t", "auto", "--target-flip", "0.02")
    assert r.returncode == 0, r.stderr
    assert "auto (target flip 0.02): Light:" in r.stdout and "pred. ꟻLIP" in r.stdout and "pred. flicker" in r.stdout
    for bad in (["--target-flip", "-0.1"], ["--target-flicker", "nan"], ["--target-flip", "0.02", "--target-flicker", "0.01"],
                ["--target-error", "0.05", "--budget-ms", "40"]):
        r = wsoft_cli("render", scene_path("box_plane.usda"), "-t", "auto", *bad, "--out", str(tmp_path / "b.exr"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (bad, r.stderr)
    for kw in ({"target_flip": float("nan")}, {"target_flicker": -1.0}, {"target_flip": 0.02, "target_flicker": 0.01}):
        with pytest.raises(ParameterError) as e:
            wsoft.render(box, "auto", width=W, height=H, device="cpu", **kw)
        assert "\n" not in str(e.value)


def test_calibrate_fits_the_flicker_model_to_moving_sequences_and_merges_modern_entries():
    """``model_from_rows`` on a few rows: the flicker model leaves a still sequence out, and an entry of
    a modern row joins the pareto row of the same frame that lacks it."""
    from wsoft.auto.calibrate import model_from_rows

    feats = [{"scene": s, "light": "/L", "features": dict(light_features_stub(), penumbra_px=p, shadowed_fraction=0.01 * p)}
             for s, p in (("a", 2.0), ("b", 6.0), ("c", 20.0))]
    seq = [dict(f, source="temporal", scene="seq_" + f["scene"]) for f in feats]

    def entry(t, params, ms, err, flip=None):
        return {"technique": t, "params": params, "frame_ms": ms, "error": {"mae_penumbra": err, "mae": err, "penumbra_pixels": 5, "flip": flip}}

    pareto = [{"scene": f["scene"], "light": "/L", "width": 64, "height": 48,
               "entries": [entry("hard", {"shadow_map_size": 1024}, 10.0 + i, 0.2, 0.01), entry("pcss", {"shadow_map_size": 1024}, 20.0 + i, 0.05, 0.004)]}
              for i, f in enumerate(feats)]
    modern = [{"scene": "a", "light": "/L", "width": 64, "height": 48, "entries": [entry("rtdenoise", {}, 30.0, 0.03)]}]
    temporal = [{"scene": f["scene"], "light": "/L", "static": f["scene"] == "seq_c",
                 "entries": [{"technique": "hard", "params": {"view": "stable"}, "frame_ms": 9.0, "temporal": {"flicker": 0.002 * (i + 1)}}]}
                for i, f in enumerate(seq)]
    m, _ = model_from_rows(pareto, feats + seq, temporal=temporal, modern=modern)
    assert m.data["source"]["modern_entries_added"] == 1 and m.data["settings"]['rtdenoise{}']["n"] == 1
    assert "flip_coef" not in m.data["settings"]['rtdenoise{}'] and set(m.settings("flip")) == {'hard{"shadow_map_size": 1024}', 'pcss{"shadow_map_size": 1024}'}
    fm = m.flicker
    assert [f["scene"] for f in fm.data["frames"]] == ["seq_a", "seq_b"]  # the still sequence is left out
    assert 0.001 < fm.predict_q(feats[0]["features"], 'hard{"view": "stable"}', "flicker") < 0.005
