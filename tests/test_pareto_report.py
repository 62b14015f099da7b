"""The cross-technique report's ranking: penumbra MAE, or the MAE over all pixels where the light casts none."""

from __future__ import annotations

import matplotlib.image as mpimg

from wsoft.bench import pareto


def _entry(technique, ms, mae, mae_penumbra, penumbra_pixels, **params):
    return {"technique": technique, "params": params, "frame_ms": ms, "shared_passes": [], "warnings": [],
            "error": {"mae": mae, "mae_penumbra": mae_penumbra, "penumbra_pixels": penumbra_pixels, "facing": {"mae": mae}}}


def _row(scene, penumbra_pixels):
    return {"scene": scene, "light": "/World/Light", "light_kind": "point" if not penumbra_pixels else "rect", "device": "cpu", "width": 64, "height": 48,
            "ground_truth_samples": 1024, "graph_passes": 10, "shared_pass_count": 2, "machine": {},
            "entries": [_entry("hard", 10.0, 0.03, 0.0 if not penumbra_pixels else 0.20, penumbra_pixels, shadow_map_size=1024),
                        _entry("hard", 20.0, 0.01, 0.0 if not penumbra_pixels else 0.18, penumbra_pixels, shadow_map_size=2048),
                        _entry("reference", 40.0, 0.0, 0.0 if not penumbra_pixels else 0.01, penumbra_pixels, samples=16)]}


def test_a_light_without_penumbra_ranks_by_the_mae_over_all_pixels(tmp_path):
    point, area = _row("tower", 0), _row("contact", 500)
    assert pareto.row_metric(point) == "mae" and pareto.row_metric(area) == "mae_penumbra"
    # penumbra MAE is 0 for any shadow of a point light: 1024² would "reach" every target; its MAE of 0.03 does not reach 0.02
    assert pareto.time_to_reach(point["entries"][:2], 0.02, pareto.row_metric(point))["params"]["shadow_map_size"] == 2048
    assert pareto.time_to_reach(point["entries"][:2], 0.02)["params"]["shadow_map_size"] == 1024
    md = tmp_path / "pareto.md"
    pareto.report([point, area], md, {"quick": False, "command": "wsoft bench pareto", "stem": "pareto"})
    text = md.read_text()
    assert "| tower | Light (all pixels) |" in text and "| contact | Light |" in text
    assert "tower/Light has no penumbra pixel" in text
    # the point light's plot has its points (it was empty when every entry was filtered out by penumbra pixels)
    img = mpimg.imread(tmp_path / "images" / "pareto" / "tower-Light-cpu.png")
    assert (img[..., :3].std(axis=-1) > 0.1).mean() > 1e-3  # coloured markers drawn


def test_the_tables_carry_flip_and_a_dash_where_a_row_has_none(tmp_path):
    area = _row("contact", 500)
    area["entries"][0]["error"]["flip"] = 0.1234
    area["entries"][2]["error"]["flip"] = 0.0056
    md = tmp_path / "pareto.md"
    pareto.report([area], md, {"quick": False, "command": "wsoft bench pareto", "stem": "pareto"})
    text = md.read_text()
    every = text.split("## Every setting")[1]
    assert "| penumbra MAE | MAE | ꟻLIP | >3se |" in every
    assert "| hard 1024² | 10.0 | 0.2000 | 0.0300 | 0.1234 |" in every and "| hard 2048² | 20.0 | 0.1800 | 0.0100 | - |" in every
    optimal = text.split("## Pareto-optimal settings")[1].split("##")[0]
    assert "| penumbra pixels | ꟻLIP |" in optimal
    assert "| reference 16 spp | 40.0 | 0.0100 | 0.0000 | 0.0000 | 500 | 0.0056 |" in optimal and "| 500 | - |" in optimal


def test_a_modern_technique_dominates_a_paper_s_only_where_its_front_is_below_every_setting(tmp_path):
    assert pareto.dominates([(10.0, 0.05)], [(20.0, 0.05), (30.0, 0.06)])
    assert not pareto.dominates([(10.0, 0.05)], [(20.0, 0.05), (30.0, 0.01)])  # the paper's slow setting is more accurate
    assert not pareto.dominates([(10.0, 0.05)], [(10.0, 0.05)])  # equal is not better
    assert not pareto.dominates([], [(1.0, 1.0)])
    won, lost = _row("contact", 500), _row("box_plane", 500)
    won["entries"] += [_entry("essm", 30.0, 0.02, 0.10, 500), _entry("msm_soft", 15.0, 0.02, 0.08, 500)]
    lost["entries"] += [_entry("essm", 30.0, 0.02, 0.05, 500), _entry("msm_soft", 15.0, 0.02, 0.08, 500)]
    md = tmp_path / "pareto.md"
    pareto.report([won, lost], md, {"quick": False, "command": "wsoft bench pareto", "stem": "pareto"})
    text = md.read_text()
    assert "| essm | 1 / 2 |" in text
    assert "`msm_soft` over `essm`: dominates on contact/Light; not on box_plane/Light." in text


def test_the_interiors_are_among_the_sweeps_frames(monkeypatch):
    """Every bundled stage outside NOT_IN_PARETO is swept, each shadow-casting light a frame: the
    lights inside closed rooms (room_lamp, corridor_torch) among them."""
    from wsoft import usd_scenes

    monkeypatch.setattr(pareto, "scene_lights", lambda name: ["/World/L"])  # no stage loaded
    swept = {c["scene"] for c in pareto.cases(False, ["cpu"])}
    assert {"room_lamp", "corridor_torch"} <= swept
    assert swept == set(usd_scenes.names()) - set(pareto.NOT_IN_PARETO)


def test_settings_a_technique_refuses_are_left_out_and_reported(tmp_path):
    """On a dome, skymaps's 256 directions of 2048² maps exceed its memory cap: that setting is left
    out of the frame's graph (one refused setting does not fail the row), kept with its reason, and
    the report names it; a quality knob on the map size itself does not repeat a setting."""
    from wsoft.bench.harness import load

    scene = load("dome_uniform")
    refused: list = []
    got = pareto.settings(scene, scene.lights[0], [1024, 2048], False, refused)
    sky = [p for t, p in got if t == "skymaps"]
    assert {"shadow_map_size": 2048, "directions": 256} not in sky and {"shadow_map_size": 2048, "directions": 16} in sky
    assert len(got) == len(set((t, tuple(sorted(p.items()))) for t, p in got))
    assert refused == [{"technique": "skymaps", "params": {"shadow_map_size": 2048, "directions": 256},
                        "reason": refused[0]["reason"]}] and "exceeds" in refused[0]["reason"]
    row = _row("contact", 500)
    row["refused_settings"] = refused
    md = tmp_path / "pareto.md"
    pareto.report([row], md, {"quick": False, "command": "wsoft bench pareto", "stem": "pareto"})
    assert "left out because the technique's own parameters refuse them (not measured): `skymaps` directions=256, shadow_map_size=2048" in md.read_text()


def test_a_setting_slower_than_the_cap_is_timed_by_its_warm_up_frame_alone(monkeypatch, tmp_path):
    """``measure(once_over_ms=...)``: a setting whose warm-up frame exceeds the cap is not rendered
    again (its frame is the warm-up's, one run, flagged), the others get their repeats; the frames
    keep the order of the settings."""
    import wsoft
    from wsoft.bench import harness

    graphs = []
    real = wsoft.render

    def counting(scene, techniques, **kw):
        graphs.append([t for t, _ in techniques])
        return real(scene, techniques, **kw)

    monkeypatch.setattr(wsoft, "render", counting)
    techs = [("pcf", {"shadow_map_size": 256}), ("reference", {"samples": 4, "seed": 1})]
    fs = harness.measure("box_plane", techs, device="cpu", width=32, height=24, light=None, repeats=2, once_over_ms=-1.0)
    assert graphs == [["pcf", "reference"]]  # the warm-up only: both over a cap below zero
    assert all(f.stats["timed_once"] and len(f.stats["timings_ms_runs"]) == 1 for f in fs.values())
    graphs.clear()
    fs = harness.measure("box_plane", techs, device="cpu", width=32, height=24, light=None, repeats=2, once_over_ms=1e9)
    assert graphs == [["pcf", "reference"]] * 3 and not any(f.stats.get("timed_once") for f in fs.values())
    assert [f.stats["technique"] for f in fs.values()] == ["pcf", "reference"]
    row = _row("contact", 500)
    row["entries"][0]["timed_once"] = True
    row["entries"][0]["frame_ms"] = 90_000.0
    md = tmp_path / "pareto.md"
    pareto.report([row], md, {"quick": False, "command": "wsoft bench pareto", "stem": "pareto"})
    assert "Timed by their warm-up frame alone (a frame over 60 s, not repeated): contact/Light hard (90 s)." in md.read_text()
