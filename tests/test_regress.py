"""The regression gate (wsoft.bench.regress): its statistics on synthetic rows, the sources it reads,
its report and exit codes, and run_sweep's --save / --baseline on a tiny sweep that renders nothing."""

from __future__ import annotations

import json
import math
import sys
import types

import pytest

from wsoft.bench import regress
from wsoft.bench.regress_rows import flatten, resolve
from wsoft.bench.regress_stats import accuracy_verdict, min_p, time_verdict
from wsoft.errors import ParameterError

ROUNDS = [100.0, 101.0, 99.0, 100.5, 99.5]


def render_row(technique: str, scene: str = "box_plane", rounds=ROUNDS, mae_p: float = 0.10, flip: float = 0.005, host: str = "vm") -> dict:
    """A row as the render sweeps (filtered, foundation) write it, trimmed to what the gate reads."""
    case = {"kind": "render", "scene": scene, "technique": technique, "params": {"shadow_map_size": 512}, "width": 160, "height": 120}
    return {"scene": scene, "technique": technique, "label": technique, "timings_ms_runs": list(rounds), "timings_ms": {"total": rounds[0]},
            "error": {"mae": 0.004, "mae_penumbra": mae_p, "penumbra_pixels": 424, "nan_pixels": 0, "flip": flip, "flip_nan_pixels": 0,
                      "facing": {"mae_penumbra": mae_p}},
            "key": json.dumps(case, sort_keys=True), "case": case, "machine": {"host": host, "threads": 2, "cpu": "x86_64"}}


def sequence_row(host: str = "vm") -> dict:
    """A row as ``temporal`` writes it: several techniques in ``entries``, per-frame times and errors."""
    case = {"kind": "sequence", "scene": "ramp_slide", "frames": "1:8", "width": 64, "height": 48}
    entries = []
    for i, t in enumerate(("dcs", "esm")):
        frames = [0.05 + 0.01 * i + 0.004 * ((k % 3) - 1) for k in range(8)]
        entries.append({"technique": t, "label": t, "frame_ms_frames": [50.0 + k % 2 for k in range(8)], "mae_penumbra_frames": frames,
                        "temporal": {"flicker": 0.01 + i * 0.02, "flicker_se": 0.0002, "mae_penumbra": sum(frames) / 8}, "flip": 0.01})
    return {"scene": "ramp_slide", "entries": entries, "key": json.dumps(case, sort_keys=True), "case": case, "machine": {"host": host, "threads": 2}}


def write(path, rows) -> str:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


def gate(tmp_path, old_rows, new_rows, *extra) -> tuple[int, str]:
    old, new = write(tmp_path / "old.jsonl", old_rows), write(tmp_path / "new.jsonl", new_rows)
    out = tmp_path / "report.md"
    rc = regress.main([old, new, "--output", str(out), *extra])
    return rc, out.read_text()


def base_rows() -> list[dict]:
    return [render_row("pcf"), render_row("pcss", mae_p=0.04), render_row("pcf", scene="contact"), sequence_row()]


def test_identical_runs_pass(tmp_path):
    rc, text = gate(tmp_path, base_rows(), base_rows())
    assert rc == 0
    assert "0 regressions, 0 improvements" in text and "### Unchanged" in text


def test_slower_with_small_spread_is_a_regression(tmp_path):
    new = base_rows()
    new[0]["timings_ms_runs"] = [t * 1.2 for t in ROUNDS]
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 1
    assert "| pcf.frame_ms |" in text.split("### Regressions")[1] and "U test p=" in text


def test_three_rounds_reject_only_when_all_separate():
    assert min_p(3, 3) == pytest.approx(0.05)
    assert time_verdict([100, 101, 99], [120, 121, 119]).kind == "worse"  # p = 1/20 = 0.05
    assert time_verdict([100, 130, 99], [120, 121, 119]).kind == "same"  # an old round above a new one: p > 0.05


def test_slower_with_huge_spread_is_not_significant(tmp_path):
    new, old = base_rows(), base_rows()
    old[0]["timings_ms_runs"] = [50.0, 100.0, 150.0, 70.0, 130.0]
    new[0]["timings_ms_runs"] = [t * 1.2 for t in (40.0, 100.0, 160.0, 60.0, 140.0)]
    assert time_verdict(old[0]["timings_ms_runs"], new[0]["timings_ms_runs"]).kind == "same"
    rc, _ = gate(tmp_path, old, new)
    assert rc == 0


def test_few_rounds_need_the_ratio_beyond_the_spread():
    assert time_verdict([100, 102], [120, 121]).kind == "worse"  # fastest new 120 > slowest old 102 x 1.1
    assert time_verdict([100, 115], [118, 122]).kind == "same"  # ratio 1.12 but 118 < 115 x 1.1
    assert time_verdict([100], [111]).kind == "worse"
    assert time_verdict([100, 102], [80, 81]).kind == "better"


def test_infinite_threshold_judges_accuracy_only(tmp_path):
    new = base_rows()
    new[0]["timings_ms_runs"] = [t * 3 for t in ROUNDS]
    rc, text = gate(tmp_path, base_rows(), new, "--time-threshold", "inf")
    assert rc == 0 and "`--time-threshold inf`" in text
    new[0]["error"]["flip"] += 0.01
    assert gate(tmp_path, base_rows(), new, "--time-threshold", "inf")[0] == 1


def test_faster_is_an_improvement(tmp_path):
    new = base_rows()
    new[1]["timings_ms_runs"] = [t * 0.7 for t in ROUNDS]
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 0
    assert "| pcss.frame_ms |" in text.split("### Improvements")[1]


def test_accuracy_change_within_noise_is_unchanged(tmp_path):
    new = base_rows()
    new[0]["error"]["mae_penumbra"] += 0.0015  # below the floor 0.002
    new[0]["error"]["flip"] += 0.0005  # below the floor 0.001
    seq = new[3]["entries"][1]  # per-frame spread: se = stdev/sqrt(8) ~ 0.0012, 3 se on both sides ~ 0.005
    seq["temporal"]["mae_penumbra"] += 0.004
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 0, text
    assert flatten(new[3])["esm.mae_penumbra"].se > 0.001
    assert accuracy_verdict(0.10, 0.104, 0.001, 0.001, floor=0.002).kind == "same"  # 0.004 < 3 x sqrt(2) x 0.001


def test_shadow_two_percent_darker_on_one_stage_is_a_regression(tmp_path):
    new = base_rows()
    for r in new:
        if r["scene"] == "contact":  # the penumbra 2 % darker at V ~ 0.5: its MAE up by 0.01
            r["error"]["mae_penumbra"] += 0.02 * 0.5
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 1
    regs = text.split("### Regressions")[1].split("###")[0]
    assert "contact" in regs and "pcf.mae_penumbra" in regs and "box_plane" not in regs


def test_vanished_row_and_entry_are_regressions(tmp_path):
    rc, text = gate(tmp_path, base_rows(), base_rows()[1:])
    assert rc == 1 and "row vanished" in text
    new = base_rows()
    del new[3]["entries"][1]
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 1 and "esm.frame_ms" in text and "metric vanished" in text


def test_nan_is_a_regression(tmp_path):
    new = base_rows()
    new[1]["error"]["mae_penumbra"] = math.nan
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 1 and "became NaN" in text
    new = base_rows()
    new[0]["error"]["nan_pixels"] = 12
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 1 and "pcf.nan_pixels" in text


def test_other_machine_judges_accuracy_only(tmp_path):
    new = [render_row("pcf", rounds=[t * 3 for t in ROUNDS], host="ci-runner"), render_row("pcss", mae_p=0.04, host="ci-runner"),
           render_row("pcf", scene="contact", host="ci-runner"), sequence_row(host="ci-runner")]
    rc, text = gate(tmp_path, base_rows(), new)
    assert rc == 0
    assert "Times not judged" in text and "host vm vs ci-runner" in text and "accuracy only" in text
    new[2]["error"]["mae_penumbra"] += 0.01
    rc, _ = gate(tmp_path, base_rows(), new)
    assert rc == 1


def test_fingerprints_of_baseline_folders(tmp_path):
    """A baseline folder's fingerprint.json: another CPU model means times are not judged."""
    for name, cpu in (("a", "CPU A"), ("b", "CPU B")):
        d = tmp_path / "baselines" / name
        d.mkdir(parents=True)
        rows = base_rows() if name == "a" else [render_row("pcf", rounds=[t * 2 for t in ROUNDS])] + base_rows()[1:]
        write(d / "filtered-quick.jsonl", rows)
        (d / "fingerprint.json").write_text(json.dumps({"cpu_model": cpu, "threads": 2, "host": "vm"}))
    assert regress.main(["a", "b", "--out-dir", str(tmp_path)]) == 0
    (tmp_path / "baselines" / "b" / "fingerprint.json").write_text(json.dumps({"cpu_model": "CPU A", "threads": 2, "host": "vm"}))
    assert regress.main(["a", "b", "--out-dir", str(tmp_path)]) == 1


def test_bad_paths_name_the_path(tmp_path, capsys):
    good = write(tmp_path / "good.jsonl", base_rows())
    for bad in (str(tmp_path / "missing.jsonl"), str(tmp_path / "nowhere"), "no_such_baseline"):
        with pytest.raises(ParameterError, match=bad.replace(".", r"\.")):
            resolve(bad, tmp_path)
        assert regress.main([good, bad, "--out-dir", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and bad in err and "Traceback" not in err
    (tmp_path / "empty").mkdir()
    with pytest.raises(ParameterError, match="holds no rows file"):
        resolve(str(tmp_path / "empty"), tmp_path)
    with pytest.raises(ParameterError, match="--time-threshold"):
        regress.check_threshold(-1.0)


def test_flatten_names_every_technique_of_a_row():
    names = set(flatten(sequence_row()))
    assert {"dcs.frame_ms", "dcs.flicker", "dcs.mae_penumbra", "dcs.flip", "esm.flicker"} <= names
    m = flatten(sequence_row())["esm.flicker"]
    assert m.kind == "accuracy" and m.se == pytest.approx(0.0002)
    pareto = {"key": "k", "entries": [{"label": "dcs(grid_size=1024)", "frame_ms_runs": [1, 2, 3], "error": {"mae_penumbra": 0.1, "flip": 0.01}}]}
    assert set(flatten(pareto)) == {"dcs(grid_size=1024).frame_ms", "dcs(grid_size=1024).mae_penumbra", "dcs(grid_size=1024).flip"}
    assert set(flatten(render_row("pcf"))) == {"pcf.frame_ms", "pcf.mae_penumbra", "pcf.flip", "pcf.nan_pixels", "pcf.flip_nan_pixels"}


def fake_sweep(darker: float = 0.0):
    """A sweep module of two rows that renders nothing (run_sweep's contract: cases, run_case, report)."""
    mod = types.ModuleType("fake_gate_sweep")
    mod.cases = lambda quick, devices: [{"kind": "render", "scene": s, "technique": "pcf"} for s in ("box_plane", "contact")]
    mod.run_case = lambda case, ctx: {k: v for k, v in render_row("pcf", scene=case["scene"], mae_p=0.1 + darker).items()
                                      if k not in ("key", "case", "machine")}
    mod.report = lambda rows, md, ctx: md.write_text(f"{len(rows)} rows\n")
    return mod


def test_run_sweep_saves_and_gates(tmp_path, monkeypatch, capsys):
    from wsoft.bench import harness

    monkeypatch.setitem(harness.SWEEPS, "fake-gate", "fake_gate_sweep")
    monkeypatch.setitem(sys.modules, "fake_gate_sweep", fake_sweep())
    out = str(tmp_path)
    assert harness.run_sweep("fake-gate", quick=True, out_dir=out, save="main") == 0
    saved = tmp_path / "baselines" / "main"
    assert len((saved / "fake-gate-quick.jsonl").read_text().splitlines()) == 2
    fp = json.loads((saved / "fingerprint.json").read_text())
    assert {"cpu_model", "threads", "warp", "wsoft", "python", "host"} <= set(fp)
    assert harness.run_sweep("fake-gate", quick=True, out_dir=out, fresh=True, baseline="main") == 0
    assert "0 regressions" in (tmp_path / "fake-gate-quick-regress.md").read_text()
    monkeypatch.setitem(sys.modules, "fake_gate_sweep", fake_sweep(darker=0.01))
    assert harness.run_sweep("fake-gate", quick=True, out_dir=out, fresh=True, baseline=str(saved)) == 1
    assert "2 regressions" in (tmp_path / "fake-gate-quick-regress.md").read_text()
    assert harness.run_sweep("fake-gate", quick=True, out_dir=out, fresh=True, baseline="main", save="main") == 1
    kept = [json.loads(line) for line in (saved / "fake-gate-quick.jsonl").read_text().splitlines()]
    assert [r["error"]["mae_penumbra"] for r in kept] == [0.1, 0.1]  # a run that regressed does not replace the baseline
    with pytest.raises(ParameterError, match="--baseline nothing_saved"):
        harness.run_sweep("fake-gate", quick=True, out_dir=out, baseline="nothing_saved")
    with pytest.raises(ParameterError, match="--save"):
        harness.run_sweep("fake-gate", quick=True, out_dir=out, save="a/b")
    capsys.readouterr()

