"""The regression gate checked both ways on a real quick sweep (the numbers of ``docs/ci.md``).

``python -m wsoft.bench.regress_proof [--sweep filtered] [--runs 10] [--out-dir DIR]`` (DIR: a temporary folder) runs the
sweep's quick version once and saves it as baseline ``proof``, reruns it ``--runs`` times against
that baseline and counts the reruns the gate fails (false alarms: the code did not change), then
judges two deliberate regressions made from the rows, against the baseline itself and against
every rerun:

- ``slower``: the round times of one technique (``--technique``, default pcf) x 1.2;
- ``darker``: on one stage (``--stage``, default box_plane) every row's penumbra MAE up by 0.01,
  what a shadow 2 % darker does at the penumbra's mean visibility 0.5 when the technique's error
  has the shift's sign.

It prints a summary and writes ``DIR/proof.md``.
"""

from __future__ import annotations

import argparse
import copy
import shutil
import sys
import tempfile
from pathlib import Path

from wsoft.bench.regress import compare_rows
from wsoft.bench.regress_rows import BASELINES, rows_of


def slower(rows: dict[str, dict], technique: str, factor: float = 1.2) -> dict[str, dict]:
    """``rows`` with every round time of ``technique``'s rows multiplied by ``factor``."""
    out = copy.deepcopy(rows)
    for r in out.values():
        if r.get("technique") == technique and "timings_ms_runs" in r:
            r["timings_ms_runs"] = [t * factor for t in r["timings_ms_runs"]]
    return out


def darker(rows: dict[str, dict], stage: str, shift: float = 0.02 * 0.5) -> dict[str, dict]:
    """``rows`` with the penumbra MAE of every row of ``stage`` raised by ``shift``."""
    out = copy.deepcopy(rows)
    for r in out.values():
        if r.get("scene") == stage and isinstance(r.get("error"), dict) and "mae_penumbra" in r["error"]:
            r["error"]["mae_penumbra"] += shift
    return out


def judged(old: dict, new: dict, metric_end: str) -> bool:
    """Whether comparing ``new`` with ``old`` finds a regression of a metric named ``*metric_end``."""
    return any(f.metric.endswith(metric_end) for f in compare_rows(old, new).regressions)


def main(argv: list[str] | None = None) -> int:
    from wsoft.bench.harness import run_sweep

    p = argparse.ArgumentParser(prog="python -m wsoft.bench.regress_proof", description=__doc__.split("\n\n")[0])
    p.add_argument("--sweep", default="filtered")
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--out-dir", default=str(Path(tempfile.gettempdir()) / "wsoft-regress-proof"))
    p.add_argument("--technique", default="pcf")
    p.add_argument("--stage", default="box_plane")
    args = p.parse_args(argv)
    d = Path(args.out_dir)
    stem = f"{args.sweep}-quick"
    shutil.rmtree(d / BASELINES / "proof", ignore_errors=True)
    run_sweep(args.sweep, quick=True, out_dir=str(d), fresh=True, save="proof")
    base = rows_of(d / BASELINES / "proof" / f"{stem}.jsonl")
    alarms, accuracy_alarms, reruns = [], 0, []
    for i in range(args.runs):
        rc = run_sweep(args.sweep, quick=True, out_dir=str(d), fresh=True, baseline="proof")
        (d / "runs").mkdir(exist_ok=True)
        shutil.copy(d / f"{stem}.jsonl", d / "runs" / f"run-{i + 1}.jsonl")
        rows = rows_of(d / f"{stem}.jsonl")
        reruns.append(rows)
        regs = compare_rows(base, rows).regressions
        accuracy_alarms += any(not f.metric.endswith("_ms") for f in regs)
        if rc:
            alarms.append(f"run {i + 1}: " + "; ".join(f"{f.row} {f.metric} {f.verdict.how}" for f in regs))
    slow_base = judged(base, slower(base, args.technique), "frame_ms")
    slow_runs = sum(judged(base, slower(r, args.technique), f"{args.technique}.frame_ms") for r in reruns)
    dark_base = judged(base, darker(base, args.stage), "mae_penumbra")
    dark_runs = sum(judged(base, darker(r, args.stage), "mae_penumbra") for r in reruns)
    loads = [r["machine"]["load"] for rows in [base, *reruns] for r in rows.values() if r.get("machine", {}).get("load") is not None]
    rounds = [r["timings_ms_runs"] for r in base.values() if r.get("technique") == args.technique and "timings_ms_runs" in r]
    L = [f"# Regression gate, checked on `wsoft bench {args.sweep} --quick`", "",
         f"Host load (1-minute average) as the rows finished: {min(loads, default=0):.1f}-{max(loads, default=0):.1f} on "
         f"{base and next(iter(base.values())).get('machine', {}).get('cores')} cores.", "",
         f"- reruns of unchanged code failed by the gate (false alarms): {len(alarms)} of {args.runs}; "
         f"by an accuracy metric, a vanished row or a NaN: {accuracy_alarms} of {args.runs}",
         *[f"  - {a}" for a in alarms],
         f"- the baseline's {args.technique} rounds: {', '.join(f'{t:.1f}' for r in rounds for t in r)} ms",
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
