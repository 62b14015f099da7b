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
from wsoft.bench.regress_stats import accuracy_verdict, min_p, sidak, time_verdict
from wsoft.errors import ParameterError

ROUNDS = [100.0, 101.0, 99.0, 100.5, 99.5, 102.0, 98.0, 100.2]  # 8 rounds, as the gate's timed rounds


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


def test_three_rounds_can_never_reach_the_corrected_level(tmp_path):
    """3 against 3 rounds give p >= 2 / C(6, 3) = 0.1 whatever they hold: never a verdict, and the
    report says so and names the metrics beyond the threshold it could not judge."""
    assert min_p(3, 3) == pytest.approx(0.1)
    assert min_p(8, 8) == pytest.approx(2 / 12870)
    v = time_verdict([100, 101, 99], [150, 151, 149], alpha=0.05)
    assert v.kind == "too few rounds" and "smallest p 0.1" in v.how
    old, new = base_rows(), base_rows()
    for r in old + new:
        for e in r.get("entries", []):
            e["frame_ms_frames"] = e["frame_ms_frames"][:3]
        if "timings_ms_runs" in r:
            r["timings_ms_runs"] = [100, 101, 99]
    new[0]["timings_ms_runs"] = [150, 151, 149]
    rc, text = gate(tmp_path, old, new)
    assert rc == 0
    assert "too few rounds** for 5 of 5 time metrics" in text and "x1.50" in text and "--rounds 16" in text
    assert text.count("smallest p 0.1") == 1  # only the metric beyond the threshold is listed


def test_slower_with_huge_spread_is_not_significant(tmp_path):
    new, old = base_rows(), base_rows()
    old[0]["timings_ms_runs"] = [50.0, 100.0, 150.0, 70.0, 130.0, 90.0, 110.0, 60.0]
    new[0]["timings_ms_runs"] = [t * 1.2 for t in (40.0, 100.0, 160.0, 60.0, 140.0, 95.0, 105.0, 70.0)]
    assert time_verdict(old[0]["timings_ms_runs"], new[0]["timings_ms_runs"]).kind == "same"
    rc, _ = gate(tmp_path, old, new)
    assert rc == 0


def test_sidak_level_over_the_runs_comparisons(tmp_path):
    assert sidak(0.05, 1) == pytest.approx(0.05)
    assert sidak(0.05, 40) == pytest.approx(0.001281, rel=1e-3)
    assert 1 - (1 - sidak(0.05, 40)) ** 40 == pytest.approx(0.05)
    # complete separation of 4 against 4 rounds: p = 2 / 70 = 0.029, significant alone, not among 40 comparisons
    assert time_verdict([100, 101, 99, 100], [120, 121, 119, 122], alpha=0.05).kind == "worse"
    assert time_verdict([100, 101, 99, 100], [120, 121, 119, 122], alpha=sidak(0.05, 40)).kind == "too few rounds"
    rc, text = gate(tmp_path, base_rows(), base_rows())
    # pcf, pcss, pcf on contact, and the sequence's dcs and esm
    assert f"5 time comparisons, each U test at level {sidak(0.05, 5):.3g}" in text


def test_threshold_and_significance_are_both_required():
    steady = [100.0 + 0.1 * i for i in range(8)]
    assert time_verdict(steady, [t * 1.05 for t in steady], alpha=0.001).kind == "same"  # significant (p = 0.00016), but 5 % < 10 %
    noisy_old = [60.0, 140.0, 90.0, 110.0, 70.0, 130.0, 80.0, 120.0]
    noisy_new = [t * 1.25 for t in (130.0, 70.0, 110.0, 90.0, 140.0, 60.0, 120.0, 80.0)]
    v = time_verdict(noisy_old, noisy_new, alpha=0.01)
    assert v.kind == "same" and v.ratio == pytest.approx(1.25)  # x1.25 but inside the rounds' spread
    assert time_verdict(steady, [t * 1.2 for t in steady], alpha=0.001).kind == "worse"
    assert time_verdict(steady, [t * 0.8 for t in steady], alpha=0.001).kind == "better"
    assert time_verdict(steady, [math.nan], alpha=0.001).kind == "worse"  # no finite time left


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



def test_timed_rounds_alternate_over_the_rows(tmp_path, monkeypatch):
    """The gate's rounds: a warm-up frame per row, then round by round over the rows, the order
    reversed every other round; only render rows of this host are timed; the gate judges them."""
    import platform

    from wsoft.bench import regress_rounds

    rows = [render_row("pcf"), render_row("pcss"), render_row("pcf", scene="contact"), sequence_row()]
    for r in rows[:3]:
        r["case"].update(device="cpu", light=None)
        r["machine"]["host"] = platform.node()
    rows[2]["machine"]["host"] = "elsewhere"
    f = tmp_path / "rows.jsonl"
    write(f, rows)
    seen = []
    monkeypatch.setattr(regress_rounds, "time_once", lambda case: seen.append(case["technique"]) or (10.0 * len(seen), 5.0 * len(seen)))
    monkeypatch.setattr(regress_rounds, "host_once", lambda: (30.0, 20.0))
    assert regress_rounds.time_rounds(f, {r["key"] for r in rows}, rounds=3) == 2
    assert seen == ["pcf", "pcss", "pcf", "pcss", "pcss", "pcf", "pcf", "pcss"]  # warm-up, round 1, round 2 reversed, round 3
    kept = [json.loads(line) for line in f.read_text().splitlines()]
    assert kept[0]["frame_ms_rounds"] == [30.0, 60.0, 70.0] and kept[1]["frame_ms_rounds"] == [40.0, 50.0, 80.0]
    assert kept[0]["frame_cpu_ms_rounds"] == [15.0, 30.0, 35.0]
    assert "frame_ms_rounds" not in kept[2] and "frame_ms_rounds" not in kept[3]
    m = flatten(kept[0])
    assert m["pcf.frame_ms"].samples == [30.0, 60.0, 70.0] and "pcf.frame_ms#2" not in m  # the rounds stand for timings_ms_runs
    assert m["pcf.frame_cpu_ms"].samples == [15.0, 30.0, 35.0]
    assert kept[0]["host_cpu_ms_rounds"] == [20.0] * 3 and kept[0]["host_ms_rounds"] == [30.0] * 3  # the host workload before each round
    assert m["pcf.frame_cpu_host_ms"].samples == [7.5, 15.0, 17.5]  # the CPU rounds in 10 ms host units
    assert not any(n.startswith("pcf.host") for n in m)  # the host's own rounds are no metric of the row
    assert regress_rounds.time_rounds(f, {r["key"] for r in rows}, rounds=0) == 0
    with pytest.raises(ParameterError, match="--rounds -1"):
        regress.check_rounds(-1)


def test_the_timer_picks_cpu_or_wall_rounds(tmp_path):
    """With CPU rounds a row's wall-clock rounds are not judged (--timer cpu, and the default host
    timer where a row has no host rounds), and the other way round with --timer wall; a time with
    no counterpart is judged either way."""
    from wsoft.bench.regress_rounds import judged_time

    old, new = base_rows(), base_rows()
    for r in old + new:
        if "timings_ms_runs" in r:
            r["frame_ms_rounds"], r["frame_cpu_ms_rounds"] = list(ROUNDS), [t / 2 for t in ROUNDS]
    new[0]["frame_ms_rounds"] = [t * 2 for t in ROUNDS]  # the wall clock doubled (a busy host), the CPU time the same
    rc, text = gate(tmp_path, old, new)
    assert rc == 0 and "CPU time" in text
    rc, text = gate(tmp_path, old, new, "--timer", "wall")
    assert rc == 1 and "| pcf.frame_ms |" in text
    new[0]["frame_cpu_ms_rounds"] = [t * 0.6 for t in ROUNDS]  # the code itself 20 % slower
    assert gate(tmp_path, old, new)[0] == 1
    for r in new:
        if "frame_cpu_ms_rounds" in r:
            r["frame_cpu_ms_rounds"] = [t * 0.65 for t in ROUNDS]  # every row 30 % slower: the host, or a change they share
    rc, text = gate(tmp_path, old, new)
    assert rc == 1 and "moved together: their median ratio is x1.30" in text
    names = {"pcf.frame_ms", "pcf.frame_cpu_ms", "esm.frame_ms"}
    assert [n for n in sorted(names) if judged_time(n, names, "cpu")] == ["esm.frame_ms", "pcf.frame_cpu_ms"]
    assert [n for n in sorted(names) if judged_time(n, names, "wall")] == ["esm.frame_ms", "pcf.frame_ms"]
    with pytest.raises(ParameterError, match="--timer gpu"):
        judged_time("pcf.frame_ms", names, "gpu")
    names |= {"pcf.frame_cpu_host_ms"}
    assert [n for n in sorted(names) if judged_time(n, names, "host")] == ["esm.frame_ms", "pcf.frame_cpu_host_ms"]
    assert [n for n in sorted(names) if judged_time(n, names, "cpu")] == ["esm.frame_ms", "pcf.frame_cpu_ms"]


def test_the_host_timer_cancels_the_host_and_keeps_the_code(tmp_path):
    """--timer host: every row's CPU time 30 % longer with the host workload 30 % longer too (a slower
    host) passes; one row 20 % slower while the host workload is unchanged (the code) fails."""
    from wsoft.bench.regress_rounds import host_once

    wall, cpu = host_once()  # the workload itself: a positive time on this host
    assert wall > 0.0 and cpu > 0.0
    old, new = base_rows(), base_rows()
    for r in old + new:
        if "timings_ms_runs" in r:
            r["frame_ms_rounds"], r["frame_cpu_ms_rounds"] = list(ROUNDS), [t / 2 for t in ROUNDS]
            r["host_cpu_ms_rounds"], r["host_ms_rounds"] = [10.0 + 0.1 * i for i in range(len(ROUNDS))], [12.0] * len(ROUNDS)
    for r in new:
        if "frame_cpu_ms_rounds" in r:
            r["frame_cpu_ms_rounds"] = [t * 1.3 for t in r["frame_cpu_ms_rounds"]]
            r["host_cpu_ms_rounds"] = [t * 1.3 for t in r["host_cpu_ms_rounds"]]
    assert gate(tmp_path, old, new, "--timer", "cpu")[0] == 1  # the CPU timer sees every row slower
    rc, text = gate(tmp_path, old, new)  # the host timer, the default
    assert rc == 0 and "host workload" in text
    new[0]["host_cpu_ms_rounds"] = [t / 1.3 for t in new[0]["host_cpu_ms_rounds"]]  # that row's host as before: its code 30 % slower
    rc, text = gate(tmp_path, old, new, "--timer", "host")
    assert rc == 1 and "| pcf.frame_cpu_host_ms |" in text
