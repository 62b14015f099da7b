"""Sweep ``distributed``: one sweep run in-process and through an embedded Dask cluster, compared.

Each row runs ``wsoft bench pareto --quick`` from scratch, as a command of its own (a fresh
process, an empty reference cache and output folder): in-process, or with ``--workers 2``
(:mod:`wsoft.bench.dist`: the first worker alone holds ``MACHINE=1`` and times, both compute
references), in alternating rounds (in-process first in even rounds, the cluster first in odd
ones; ``--quick``: one round).
The report gives each run's wall time and their ratio within a round, checks that every error
figure of every setting is equal across the runs (same seeds, same references), and groups the
rows' frame times by host, with the workers' scene loads and kernel compiles apart.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

INNER = "pareto"  # the sweep compared (its quick form)
WORKERS = 2
MODES = ("in-process", f"workers={WORKERS}")


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    for r in range(1 if quick else 2):
        for mode in (MODES if r % 2 == 0 else MODES[::-1]):
            out.append({"kind": "run", "sweep": INNER, "mode": mode, "round": r, "device": devices[0]})
    return out


def _slim(row: dict) -> dict:
    """What the comparison reads of an inner row: where it ran and each setting's error and time."""
    w = row.get("worker", {})
    return {"key": row["key"], "scene": row["scene"], "light": row["light"], "host": row["machine"].get("host"),
            "load": row["machine"].get("load"), "threads": row["machine"].get("threads"), "pid": w.get("pid"),
            "scene_load_s": w.get("scene_load_s"), "scene_was_loaded": w.get("scene_was_loaded"), "compile_s": w.get("compile_s"),
            "row_seconds": row["row_seconds"],
            "entries": [{"label": e["label"], "error": e["error"], "frame_ms": e["frame_ms"]} for e in row["entries"]]}


def command(case: dict, out_dir: Path) -> list[str]:
    """The inner run's command line (this Python, wsoft's command line)."""
    return [sys.executable, "-m", "wsoft.cli", "bench", case["sweep"], "--quick", "--device", case["device"], "--out-dir", str(out_dir),
            "--fresh"] + (["--workers", str(WORKERS)] if case["mode"] != "in-process" else [])


def run_case(case: dict, ctx: dict) -> dict:
    from wsoft.bench.harness import finished_rows
    from wsoft.errors import ParameterError

    with tempfile.TemporaryDirectory(prefix="wsoft-distributed-") as tmp:
        env = dict(os.environ, WSOFT_CACHE_DIR=str(Path(tmp) / "cache"))  # references computed in every run
        t0 = time.perf_counter()
        p = subprocess.run(command(case, Path(tmp) / "out"), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        wall = time.perf_counter() - t0
        if p.returncode not in (0, 1):
            raise ParameterError(f"wsoft bench {case['sweep']} --quick ({case['mode']}) exited {p.returncode}: "
                                 + (p.stderr.strip().splitlines() or ["no message"])[-1])
        rows = finished_rows(Path(tmp) / "out" / f"{case['sweep']}-quick.jsonl")
    return {"mode": case["mode"], "round": case["round"], "sweep": case["sweep"], "device": case["device"], "rc": p.returncode,
            "wall_s": round(wall, 2), "rows": [_slim(r) for r in rows]}


def _errors(run: dict) -> dict[tuple[str, str], dict]:
    return {(r["key"], e["label"]): e["error"] for r in run["rows"] for e in r["entries"]}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    L = [f"# Sweep `distributed`{' (quick)' if ctx['quick'] else ''}: `wsoft bench {INNER} --quick` in-process and on Dask", ""]
    L.append(f"Produced by `{ctx['command']}` (rows: `{md.with_suffix('.jsonl').name}`; rerun resumes, `--fresh` starts over).")
    L.append(f"Each row runs `wsoft bench {INNER} --quick --fresh` from scratch as a command of its own (a fresh process, its own "
             "empty reference cache; the wall time is the command's, Python's start and imports included): in-process, or with "
             f"`--workers {WORKERS}`: an embedded Dask LocalCluster of {WORKERS} spawned worker processes, one thread each, the first "
             "holding `MACHINE=1` (it alone runs the timed jobs, one at a time) and both computing the references (error-only jobs). "
             "Rounds alternate which runs first.")
    L.append("")
    if not rows:
        md.write_text("\n".join(L) + "\n")
        return
    L += ["## Wall time", "", "| round | run | wall s | rows | hosts | exit |", "|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["round"], r["mode"])):
        hosts = sorted({x["host"] for x in r["rows"]})
        L.append(f"| {r['round']} | {r['mode']} | {r['wall_s']:.1f} | {len(r['rows'])} | {', '.join(hosts)} | {r['rc']} |")
    ratios = []
    for rnd in sorted({r["round"] for r in rows}):
        both = {r["mode"]: r for r in rows if r["round"] == rnd}
        if set(both) == set(MODES):
            ratios.append(both[MODES[1]]["wall_s"] / both[MODES[0]]["wall_s"])
    if ratios:
        L += ["", f"Wall time of `--workers {WORKERS}` over in-process, per round: {', '.join(f'{x:.2f}' for x in ratios)}. "
              "The cluster's time includes starting it (spawning the workers, importing wsoft in each) and each worker's warm-up; "
              "with one timing worker the timed jobs run one at a time, as in-process, and only the references run beside them."]
        same = [r for r in rows if r["mode"] == MODES[0]]
        if len(same) > 1:
            a, b = sorted(same, key=lambda r: r["round"])[:2]
            L.append(f"The two in-process runs' ratio, {b['wall_s'] / a['wall_s']:.2f}, is this machine's noise between rounds.")
    L += ["", "## Error figures", ""]
    base = next(r for r in sorted(rows, key=lambda r: (r["round"], r["mode"] != MODES[0])))
    ref = _errors(base)
    for r in rows:
        if r is base:
            continue
        other = _errors(r)
        same = sum(other.get(k) == v for k, v in ref.items())
        missing = len(set(ref) ^ set(other))
        L.append(f"* round {r['round']} {r['mode']}: {same} of {len(ref)} settings' error figures (every metric: MAE, penumbra MAE, "
                 f"RMSE, ꟻLIP, ...) equal to round {base['round']} {base['mode']}'s" + (f"; {missing} settings in one run only" if missing else "") + ".")
    L += ["", "## Frame times by host", "",
          "Times are compared only within one host. Per run and host: the rows, the hosts' 1-minute load as rows finished, the "
          "median over every setting of its frame ms, and the ratio of each setting's frame ms to the same setting's in the "
          "first in-process run on that host (median over settings).", "",
          "| round | run | host | rows | load | median frame ms | frame ms / in-process (median) |", "|---|---|---|---|---|---|---|"]
    base_ms = {(x["host"], x["key"], e["label"]): e["frame_ms"] for x in base["rows"] for e in x["entries"]}
    for r in sorted(rows, key=lambda r: (r["round"], r["mode"])):
        for host in sorted({x["host"] for x in r["rows"]}):
            mine = [x for x in r["rows"] if x["host"] == host]
            ms = [e["frame_ms"] for x in mine for e in x["entries"]]
            rel = [e["frame_ms"] / base_ms[(host, x["key"], e["label"])] for x in mine for e in x["entries"]
                   if base_ms.get((host, x["key"], e["label"]), 0) > 0]
            loads = [x["load"] for x in mine if x["load"] is not None]
            L.append(f"| {r['round']} | {r['mode']} | {host} | {len(mine)} | {min(loads):.1f}-{max(loads):.1f} | {statistics.median(ms):.2f} | "
                     + (f"{statistics.median(rel):.2f}" if rel else "-") + " |")
    L += ["", "## Warm-up on the workers", "",
          "Per cluster run and worker process that ran timed jobs: its scene loads with their BVH builds (once per worker and scene; "
          "the first also holds Warp's start), the kernel compiles and loads within its timed jobs and their scenes' warm-up, and "
          "the seconds of its jobs, warm-up included.", "", "| round | host | worker pid | scenes loaded | load + BVH s | compile s | job s |",
          "|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: r["round"]):
        if r["mode"] == MODES[0]:
            continue
        for (host, pid) in sorted({(x["host"], x["pid"]) for x in r["rows"]}, key=str):
            mine = [x for x in r["rows"] if (x["host"], x["pid"]) == (host, pid)]
            loads = {x["scene"]: x["scene_load_s"] for x in mine}
            L.append(f"| {r['round']} | {host} | {pid} | {', '.join(sorted(loads))} | {sum(loads.values()):.2f} | "
                     f"{sum(x['compile_s'] for x in mine):.2f} | {sum(x['row_seconds'] for x in mine):.1f} |")
    md.write_text("\n".join(L) + "\n")
