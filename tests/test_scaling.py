"""The scaling sweep's pieces that need no render: its stage family, its cases and budget, and the
report's fits, flags, prediction and sections (written from rows made up here)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wsoft.bench import scaling, scaling_report
from wsoft.bench.scaling_report import (
    exponents,
    fit,
    implied,
    log_exponent,
    missing_rows,
    predict_ms,
    size_of,
    work_exponent,
)


def test_the_sheet_has_the_triangles_asked_for_and_its_holes():
    for n in (2_000, 100_000):
        pts, tris = scaling.sheet_arrays(n)
        assert abs(len(tris) - n) / n < 0.05
        assert tris.min() == 0 and tris.max() < len(pts)
        k = int(round(math.sqrt(len(pts)))) - 1
        assert len(tris) == 2 * (k * k - (k // 2) ** 2)  # every fourth cell is a hole
        assert np.all((pts[:, 2] > 0.9) & (pts[:, 2] < 1.1))  # about 1 above the ground


def test_cases_cover_every_axis_cheapest_first():
    cs = scaling.cases(True, ["cpu"])
    axes = list(dict.fromkeys(c["axis"] for c in cs))
    assert axes == ["triangles", "pixels", "loading", "lights", "instances", "map"]
    full = scaling.cases(False, ["cpu"])
    tri = [c["value"] for c in full if c["axis"] == "triangles"]
    assert tri[0] == 10_000 and tri[-1] == 10_000_000
    assert [c["value"] for c in full if c["axis"] == "pixels"][-1] == [1920, 1080]
    assert [c["value"] for c in full if c["axis"] == "map"][-1] == 8192
    assert [c["value"] for c in full if c["axis"] == "lights"] == [1, 4, 16, 64]
    assert [c["value"] for c in full if c["axis"] == "instances"][-1] == 1_000_000


def _row(axis, value, times, **extra):
    return {"axis": axis, "value": value, "device": "cpu", "machine": {"cpu": "x86_64", "threads": 2, "load": 1.0}, "triangles": extra.pop("triangles", 100_000), "width": 320, "height": 240,
            "techniques": {t: ({"ms": ms} if ms is not None else {"ms": None, "predicted_s": 99.0}) | extra.get(t, {})
                           for t, ms in times.items()}}


def test_the_budget_reads_a_frame_of_many_lights_once():
    """On the lights axis the earlier rows' times hold every light already: 1 s at one light and 4 s at
    four predict 16 s at sixteen, inside the budget (a prediction multiplied again by the lights,
    256 s, would have left the technique out)."""
    earlier = [_row("lights", 1, {"pcss": 1000.0}), _row("lights", 4, {"pcss": 4000.0})]
    pred = scaling._predicted_s({"axis": "lights", "value": 16}, "pcss", earlier)
    assert pred == pytest.approx(16.0)
    assert not scaling.over_budget(pred)
    assert scaling.over_budget(scaling._predicted_s({"axis": "lights", "value": 64}, "pcss", earlier + [_row("lights", 16, {"pcss": 16000.0})]))
    assert not scaling.over_budget(None)
    assert scaling._predicted_s({"axis": "lights", "value": 16}, "hard", earlier) is None
    # one earlier point: linear
    assert scaling._predicted_s({"axis": "lights", "value": 4}, "pcss", earlier[:1]) == pytest.approx(4.0)


def test_fit_recovers_a_power_law_and_needs_two_sizes():
    xs = [1e4, 1e5, 1e6]
    assert fit(xs, [3.0 * x**0.7 for x in xs]) == pytest.approx(0.7)
    assert fit([1e4], [5.0]) is None
    assert fit([1e4, 1e4], [5.0, 6.0]) is None


def test_log_n_is_a_small_positive_exponent_over_the_measured_sizes():
    k = log_exponent([1e4, 1e5, 1e6, 1e7])
    assert 0.03 < k < 0.15
    assert log_exponent([1e4]) == 0.0
    assert implied("reference", "triangles", [1e4, 1e7])[0] == pytest.approx(log_exponent([1e4, 1e7]))
    assert implied("pcss", "triangles", [1e4, 1e7])[0] == 1.0
    assert implied("reference", "map")[0] == 0.0
    assert implied("pcss", "pixels")[0] == 1.0


def test_the_own_work_count_explains_a_superlinear_time():
    """dcs's time is linear in its wedge tests, which grow as triangles^1.3: against triangles it is
    over the implied 1.0, against its own work it is 1.0."""
    rows = [_row("triangles", t, {"dcs": 1e-5 * t**1.3}, triangles=t,
                 dcs={"counters": {"wedge_tests": int(100 * t**1.3), "grid_size": g}})
            for t, g in ((10_000, 128), (100_000, 64), (1_000_000, 16))]
    e = exponents(rows)["triangles"]["dcs"]
    assert e["fitted"] == pytest.approx(1.3, abs=1e-3) and e["over"]
    assert e["work"] == pytest.approx(1.0, abs=1e-3) and e["work_name"] == "wedge tests"
    assert work_exponent("pcss", e["points"]) == (None, "")


def test_prediction_adds_each_axis_growth_and_repeats_it_per_light():
    base = {"triangles": 1e5, "pixels": 320 * 240, "lights": 1.0}
    t = predict_ms(100.0, {"triangles": 0.5, "pixels": 1.0, "lights": None}, base,
                   {"triangles": 4e5, "pixels": 640 * 480, "lights": 8.0})
    assert t == pytest.approx(100.0 + 100.0 + 300.0)  # what each axis added, added; no lights exponent: unchanged
    t = predict_ms(100.0, {"triangles": 0.5, "pixels": 1.0, "lights": 1.0}, base, {"triangles": 4e5, "pixels": 640 * 480, "lights": 8.0})
    assert t == pytest.approx(500.0 * 8.0)  # repeated per light
    assert predict_ms(100.0, {"triangles": 0.5}, base, base) == pytest.approx(100.0)


def _rows():
    rows = []
    for t in (10_000, 100_000, 1_000_000):
        rows.append(_row("triangles", t, {"reference": 100.0 * (math.log2(t) / 13.3), "pcss": 40.0 * (t / 1e4) ** 0.3,
                                          "dcs": 1e-4 * t**1.3 if t < 1_000_000 else None}, triangles=t,
                         dcs={"counters": {"wedge_tests": int(t**1.3), "grid_size": 64}}, pcss={"gbuffer_ms": 5.0}))
    for w, h in ((160, 120), (320, 240)):
        rows.append(_row("pixels", [w, h], {"pcss": w * h / 1000.0}))
    for n in (1, 4):
        rows.append(_row("lights", n, {"pcss": 40.0 * n}, pcss={"gbuffer_ms": 5.0, "rss_peak_mib": 100.0, "device_bytes": 2**20}))
    for t in (10_000, 100_000):
        rows.append({"axis": "loading", "value": t, "device": "cpu", "machine": {"load": 1.0}, "triangles": t, "usd_read_s": 1e-6 * t, "load_s": 3e-6 * t,
                     "upload_s": 1e-6 * t, "embree_build_s": 5e-7 * t, "rss_peak_mib": 200.0})
    return rows


def test_the_report_has_its_tables_plots_flags_prediction_and_loading(tmp_path):
    rows = _rows()
    md = tmp_path / "scaling.md"
    scaling.report(rows, md, {"quick": False, "command": "wsoft bench scaling", "stem": "scaling", "out_dir": tmp_path})
    text = md.read_text()
    for axis in ("triangles", "pixels", "lights", "loading"):
        assert (tmp_path / "images" / "scaling" / f"{axis}.png").stat().st_size > 5_000
        assert f"images/scaling/{axis}.png" in text
    assert "## Against triangles" in text and "| fitted | last two | implied |" in text
    assert "`dcs` against triangles" in text and "wedge tests" in text  # flagged, with its own work's exponent
    assert "`reference` against triangles" not in text  # log n: not flagged
    assert "(99000)" in text  # a point left out shows its prediction
    assert "## Predicting a frame's time on your own stage" in text
    assert "## Loading: the stage on disk to the first pass" in text and "embreex" in text
    assert "G-buffer runs once a frame" in text
    assert "## Rows not measured" in text and "instances = 1000000" in text  # the rows not in the file are listed
    assert "nan" not in text.lower()


def test_missing_rows_are_the_cases_no_row_holds():
    rows = [json.loads(json.dumps(r)) for r in _rows()]  # values as the jsonl gives them back
    miss = missing_rows(rows, scaling.cases(False, ["cpu"]))
    assert ("pixels", [160, 120]) not in miss and ("pixels", [1920, 1080]) in miss
    assert ("loading", 10_000) not in miss and ("loading", 1_000_000) in miss
    assert size_of(rows[3]) == 160 * 120
    assert scaling_report.AXES[0] == "triangles"


def test_an_axis_is_read_by_cpu_time_only_where_every_point_has_it():
    from wsoft.bench.scaling_report import timer

    both = [_row("lights", n, {"pcss": 10.0 * n}, pcss={"cpu_ms": 20.0 * n}) for n in (1, 4)]
    assert timer(both) == "cpu_ms"
    assert timer(both + [_row("lights", 16, {"pcss": 160.0})]) == "ms"  # one point without it: wall time for the whole axis
    assert exponents(both)["lights"]["pcss"]["timer"] == "cpu_ms"


def test_a_techniques_cpu_time_leaves_out_the_scene_and_gbuffer():
    stats = {"cpu_ms": {"gbuffer": 5.0, "pcss.map": 3.0, "pcss.filter": 4.0, "shade": 1.0},
             "pass_kinds": {"gbuffer": "gbuffer", "pcss.map": "light_map", "pcss.filter": "technique", "shade": "shade"}}
    assert scaling.technique_cpu_ms(stats) == pytest.approx(7.0)


def test_an_axis_read_by_wall_time_at_mixed_loads_is_flagged():
    from wsoft.bench.scaling_report import mixed_load

    rows = [_row("instances", n, {"pcss": 10.0 * n}) for n in (1, 10)]
    rows[0]["machine"]["load"], rows[1]["machine"] = 1.5, {"load": 4.8}
    assert mixed_load(rows) == (1.5, 4.8)
    rows[1]["machine"]["load"] = 2.5
    assert mixed_load(rows) is None  # within 2x
    cpu = [_row("lights", n, {"pcss": 10.0 * n}, pcss={"cpu_ms": 5.0 * n}) for n in (1, 4)]
    cpu[1]["machine"] = {"load": 9.0}
    assert mixed_load(cpu) is None  # read by CPU time
