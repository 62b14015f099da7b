"""The regression gate checked both ways on a real quick sweep (the numbers of ``docs/ci.md``).

``python -m wsoft.bench.regress_proof [--sweep filtered] [--runs 10] [--rounds 16] [--out-dir DIR]`` (DIR: a temporary folder) runs the
sweep's quick version once and saves it as baseline ``proof``, reruns it ``--runs`` times against
that baseline and counts, for each timer the gate offers (cpu, host, wall: the rows keep every
round's times, so all are judged on the same runs), the reruns the gate fails (false alarms: the
code did not change), then judges two deliberate regressions made from the rows, against the
baseline itself and against every rerun:

- ``slower``: the round times of one technique (``--technique``, default pcf; the sweep's and the
  gate's timed rounds) x 1.2;
- ``darker``: on one stage (``--stage``, default box_plane) every row's penumbra MAE up by 0.01,
  what a shadow 2 % darker does at the penumbra's mean visibility 0.5 when the technique's error
  has the shift's sign.

It prints a summary and writes ``DIR/proof.md``.
"""

from __future__ import annotations

import argparse
import copy
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

from wsoft.bench.regress import compare_rows
from wsoft.bench.regress_rounds import CPU_KEY, DEFAULT_TIMER, HOST_KEY, KEY, ROUNDS, TIMERS, host_scaled, judged_time, scaled
from wsoft.bench.regress_rows import BASELINES, flatten, rows_of
from wsoft.bench.regress_stats import TIME_THRESHOLD


SLOW_METRIC = {"cpu": "frame_cpu_ms", "host": "frame_cpu_host_ms", "wall": "frame_ms"}  # the time metric each timer judges


def slower(rows: dict[str, dict], technique: str, factor: float = 1.2) -> dict[str, dict]:
    """``rows`` with every round time of ``technique``'s rows (the sweep's and the gate's timed
    rounds) multiplied by ``factor``."""
    return {k: scaled(r, factor) if r.get("technique") == technique else copy.deepcopy(r) for k, r in rows.items()}


def darker(rows: dict[str, dict], stage: str, shift: float = 0.02 * 0.5) -> dict[str, dict]:
    """``rows`` with the penumbra MAE of every row of ``stage`` raised by ``shift``."""
    out = copy.deepcopy(rows)
    for r in out.values():
        if r.get("scene") == stage and isinstance(r.get("error"), dict) and "mae_penumbra" in r["error"]:
            r["error"]["mae_penumbra"] += shift
    return out


def judged(old: dict, new: dict, metric_end: str, timer: str = DEFAULT_TIMER) -> bool:
    """Whether comparing ``new`` with ``old`` finds a regression of a metric named ``*metric_end``."""
    return any(f.metric.endswith(metric_end) for f in compare_rows(old, new, timer=timer).regressions)


def time_ratios(old: dict, new: dict, timer: str = DEFAULT_TIMER) -> list[float]:
    """The ratio of medians new/old of every time metric two runs share that the gate judges."""
    import statistics

    out = []
    for key, ro in old.items():
        if key not in new:
            continue
        mo, mn = flatten(ro), flatten(new[key])
        for name, a in mo.items():
            b = mn.get(name)
            if a.kind == "time" and judged_time(name, mo, timer) and b is not None and a.samples and b.samples and statistics.median(a.samples) > 0:
                out.append(statistics.median(b.samples) / statistics.median(a.samples))
    return out


def main(argv: list[str] | None = None) -> int:
    from wsoft.bench.harness import run_sweep

    p = argparse.ArgumentParser(prog="python -m wsoft.bench.regress_proof", description=__doc__.split("\n\n")[0])
    p.add_argument("--sweep", default="filtered")
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--rounds", type=int, default=ROUNDS, help=f"the gate's timed rounds per render row (default {ROUNDS})")
    p.add_argument("--timer", choices=TIMERS, default=DEFAULT_TIMER, help="the time each rerun's own gate judges; the proof judges every timer")
    p.add_argument("--out-dir", default=str(Path(tempfile.gettempdir()) / "wsoft-regress-proof"))
    p.add_argument("--technique", default="pcf")
    p.add_argument("--stage", default="box_plane")
    args = p.parse_args(argv)
    d = Path(args.out_dir)
    stem = f"{args.sweep}-quick"
    t0, began = time.time(), time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    shutil.rmtree(d / BASELINES / "proof", ignore_errors=True)
    run_sweep(args.sweep, quick=True, out_dir=str(d), fresh=True, save="proof", rounds=args.rounds, timer=args.timer)
    base = rows_of(d / BASELINES / "proof" / f"{stem}.jsonl")
    reruns = []
    for i in range(args.runs):
        run_sweep(args.sweep, quick=True, out_dir=str(d), fresh=True, baseline="proof", rounds=args.rounds, timer=args.timer)
        (d / "runs").mkdir(exist_ok=True)
        shutil.copy(d / f"{stem}.jsonl", d / "runs" / f"run-{i + 1}.jsonl")
        reruns.append(rows_of(d / f"{stem}.jsonl"))
    loads = [r["machine"]["load"] for rows in [base, *reruns] for r in rows.values() if r.get("machine", {}).get("load") is not None]
    hi = 1 + TIME_THRESHOLD
    L = [f"# Regression gate, checked on `wsoft bench {args.sweep} --quick`", "",
         f"`python -m wsoft.bench.regress_proof --sweep {args.sweep} --runs {args.runs} --rounds {args.rounds} --out-dir {args.out_dir}`, "
         f"from {began} UTC, {(time.time() - t0) / 60:.1f} minutes.", "",
         f"Host load (1-minute average) as the rows finished: {min(loads, default=0):.1f}-{max(loads, default=0):.1f} on "
         f"{base and next(iter(base.values())).get('machine', {}).get('cores')} cores. Timed rounds per render row: {args.rounds}. "
         "Every timer is judged on the same runs (the rows keep each round's wall-clock, CPU and host-workload times).", ""]
    for timer in TIMERS:
        alarms, accuracy_alarms, tests, ratios = [], 0, set(), []
        for i, rows in enumerate(reruns):
            c = compare_rows(base, rows, timer=timer)
            tests.add((c.time_comparisons, round(c.time_level, 5), len(c.few_rounds)))
            ratios += time_ratios(base, rows, timer)
            regs = c.regressions
            accuracy_alarms += any(not f.metric.endswith("_ms") for f in regs)
            if regs:
                alarms.append(f"run {i + 1}: " + "; ".join(f"{f.row} {f.metric} {f.verdict.how}" for f in regs))
        slow = f"{args.technique}.{SLOW_METRIC[timer]}"
        slow_base = judged(base, slower(base, args.technique), slow, timer)
        slow_runs = sum(judged(base, slower(r, args.technique), slow, timer) for r in reruns)
        dark_base = judged(base, darker(base, args.stage), "mae_penumbra", timer)
        dark_runs = sum(judged(base, darker(r, args.stage), "mae_penumbra", timer) for r in reruns)
        rounds = [host_scaled(r[CPU_KEY], r[HOST_KEY]) if timer == "host" else r.get(CPU_KEY if timer == "cpu" else KEY) or r["timings_ms_runs"]
                  for r in base.values() if r.get("technique") == args.technique and "timings_ms_runs" in r and CPU_KEY in r]
        beyond = sum(r > hi or r < 1 / hi for r in ratios)
        L += [f"## `--timer {timer}`", "",
              "- time comparisons per rerun, each U test's Šidák-corrected level, metrics with too few rounds: "
              + "; ".join(f"{k}, {lv:g}, {few}" for k, lv, few in sorted(tests)),
              f"- ratios of medians new/old over the reruns' time metrics: x{min(ratios, default=math.nan):.2f} to x{max(ratios, default=math.nan):.2f}; "
              f"{beyond} of {len(ratios)} beyond the threshold x{hi:.2f} either way (those the rank test had to judge)",
              f"- reruns of unchanged code failed by the gate (false alarms): {len(alarms)} of {args.runs}; "
              f"by an accuracy metric, a vanished row or a NaN: {accuracy_alarms} of {args.runs}",
              *[f"  - {a}" for a in alarms],
              f"- the baseline's {args.technique} rounds ({timer}): {', '.join(f'{t:.1f}' for r in rounds for t in r)} ms",
              f"- {args.technique} 20 % slower: caught against the baseline's own rows: {'yes' if slow_base else 'no'}; "
              f"in {slow_runs} of {args.runs} reruns",
              f"- {args.stage} shadow 2 % darker (penumbra MAE +0.01): caught against the baseline's own rows: {'yes' if dark_base else 'no'}; "
              f"in {dark_runs} of {args.runs} reruns", ""]
    text = "\n".join(L)
    (d / "proof.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
