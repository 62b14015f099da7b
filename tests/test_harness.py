"""Harness core: rows are appended as they finish, a rerun resumes, the report is written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wsoft.bench import harness


@pytest.fixture
def tiny(monkeypatch, tmp_path):
    """A two-row sweep on box_plane so the test is quick; references cached in tmp."""
    import wsoft.bench.foundation as fnd

    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path / "cache"))
    calls = []

    def cases(quick, devices):
        return [
            {"kind": "render", "scene": "box_plane", "light": None, "device": devices[0], "width": 48, "height": 36, "ref_samples": 16,
             "technique": "hard", "params": {"shadow_map_size": s}, "image": s == 512}
            for s in (256, 512)
        ]

    real = fnd.run_case

    def run_case(case, ctx):
        calls.append(case["params"]["shadow_map_size"])
        return real(case, ctx)

    monkeypatch.setattr(fnd, "cases", cases)
    monkeypatch.setattr(fnd, "run_case", run_case)
    return tmp_path / "reports", calls


def test_rows_resume_and_report(tiny):
    out, calls = tiny
    assert harness.run_sweep("foundation", quick=True, device=["cpu"], out_dir=str(out)) == 0
    rows = harness.read_rows(out / "foundation-quick.jsonl")
    assert [r["params"]["shadow_map_size"] for r in rows] == [256, 512] and calls == [256, 512]
    r = rows[0]
    for k in ("scene", "technique", "params", "device", "width", "height", "timings_ms", "memory_bytes", "error"):
        assert k in r
    assert set(r["error"]) >= {"mae", "rmse", "max", "mae_penumbra", "frac_outside_3se", "flip", "flip_covered"}
    assert 0 <= r["error"]["mae"] <= 1 and 0 < r["error"]["flip"] <= 1
    md = (out / "foundation-quick.md").read_text()
    assert "wsoft bench foundation --quick" in md and "| box_plane |" in md
    assert (out / "images" / "foundation-quick" / "error_vs_time.png").exists()
    # a rerun computes nothing; losing the last row (an interrupted sweep) recomputes only it
    harness.run_sweep("foundation", quick=True, device=["cpu"], out_dir=str(out))
    assert calls == [256, 512]
    lines = (out / "foundation-quick.jsonl").read_text().splitlines()
    (out / "foundation-quick.jsonl").write_text(lines[0] + "\n" + lines[1][:40])  # cut short mid-row
    harness.run_sweep("foundation", quick=True, device=["cpu"], out_dir=str(out))
    assert calls == [256, 512, 512]
    assert len(harness.read_rows(out / "foundation-quick.jsonl")) == 2


def test_reference_is_cached(tiny):
    a = harness.reference("box_plane", width=32, height=24, light=None, samples=4)
    b = harness.reference("box_plane", width=32, height=24, light=None, samples=4)
    assert not a["cached"] and b["cached"]
    assert np.array_equal(a["V"], b["V"])
    c = harness.reference("box_plane", width=32, height=24, light=None, samples=9)
    assert not c["cached"]


def test_unknown_sweep(tiny):
    import wsoft

    with pytest.raises(wsoft.ParameterError, match="unknown sweep .nope.; sweeps: adversarial, auto, cube, distributed, essm, essm-table1, essm-table2, filtered, foundation"):
        harness.run_sweep("nope", out_dir=str(tiny[0]))


def test_metrics_on_known_images():
    from wsoft.metrics import visibility_error

    ref = np.array([[0.0, 0.5], [1.0, 1.0]])
    v = np.array([[0.0, 0.7], [1.0, 0.0]])
    se = np.full_like(ref, 0.05)
    cov = np.array([[1, 1], [1, 0]])
    e = visibility_error(v, ref, se, cov)
    assert e["pixels"] == 3 and e["mae"] == pytest.approx(0.2 / 3) and e["max"] == pytest.approx(0.2)
    assert e["mae_penumbra"] == pytest.approx(0.2) and e["penumbra_pixels"] == 1
    assert e["frac_outside_3se"] == pytest.approx(1 / 3)
    assert json.dumps(e)


def test_modern_sweep_states_its_targets(tmp_path):
    """``wsoft bench modern --quick``: the modern techniques beside the baselines on the same frames,
    the stacked stage's leak per technique, and every target as a row (met or not, never left out)."""
    out = tmp_path / "reports"
    assert harness.run_sweep("modern", quick=True, device=["cpu"], out_dir=str(out)) == 0
    md = (out / "modern-quick.md").read_text()
    assert "## Targets" in md and md.count("| rtdenoise (defaults) on ") == 3 and "msm's leak ≤ half of vsm's on stacked_plates | msm " in md
    for t in ("rtdenoise", "msm", "msm_soft", "evsm", "vsm", "reference"):
        assert f"| box_plane | Light | {t}" in md, t
    assert "## Light leak per technique" in md and "(images/modern-quick/box_plane-rtdenoise.png)" in md
    assert (out / "images" / "modern-quick" / "box_plane-rtdenoise.png").is_file()


@pytest.mark.slow
def test_temporal_sweep_measures_flicker_per_technique(tmp_path):
    """``wsoft bench temporal --quick``: every technique over the quick sequences with its flicker, mean
    error and ꟻLIP, stable views and rtdenoise's history beside the defaults, the crawl target as a row,
    and a rerun that resumes (no row computed twice)."""
    out = tmp_path / "reports"
    assert harness.run_sweep("temporal", quick=True, device=["cpu"], out_dir=str(out)) == 0
    rows = harness.read_rows(out / "temporal-quick.jsonl")
    assert [r["scene"] for r in rows] == ["ramp_slide", "ramp_static"]
    for r in rows:
        labels = {e["label"] for e in r["entries"]}
        assert {"hard(shadow_map_size=256)", "rtdenoise", "rtdenoise(history=8)"} <= labels
        assert any("view=stable" in l for l in labels) and any("view=sequence" in l for l in labels)
        for e in r["entries"]:
            assert e["temporal"]["pairs"] == 2 and e["temporal"]["paired_pixels"] > 0 and e["flip"] is not None
    static = next(r for r in rows if r["scene"] == "ramp_static")
    assert static["static"] and all("temporal_std" in e["temporal"] for e in static["entries"])
    hard = next(e for e in static["entries"] if e["label"] == "hard(shadow_map_size=256)")
    assert hard["temporal"]["flicker"] == 0.0 and hard["temporal"]["temporal_std"] == 0.0  # a still stage, a deterministic map
    md = (out / "temporal-quick.md").read_text()
    assert "## Targets" in md and "on the still ramp_static" in md and "| ramp_slide | Light |" in md
    assert (out / "images" / "temporal-quick" / "ramp_slide-Light-flicker.png").is_file()
    first = (out / "temporal-quick.jsonl").read_text()
    assert harness.run_sweep("temporal", quick=True, device=["cpu"], out_dir=str(out)) == 0
    assert (out / "temporal-quick.jsonl").read_text() == first
