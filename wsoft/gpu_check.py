"""``python -m wsoft.gpu_check``: one command for a GPU lent for a few minutes.

It reports the device, runs the test suite with ``cuda:0`` as the tests' device, runs every quick
sweep on the device *and* on the CPU (so each row has both figures from the same run), and writes
``reports/gpu-check.md``: the device, the tests' outcome, and per sweep each row's frame (or build)
time on the CPU beside the device's, with the speed-up. ``--device cpu`` runs the same steps on
the CPU alone (to time the check itself where no GPU is lent). A time budget (``--budget-s``,
default 540 s) stops before a step that would start past it and says which steps did not run.

    python -m wsoft.gpu_check                     # cuda:0, tests + quick sweeps, reports/gpu-check.md
    python -m wsoft.gpu_check --device cpu --out-dir /tmp/check
    python -m wsoft.gpu_check --skip-tests --sweeps foundation,essm-table1
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

QUICK_SWEEPS = ("foundation", "filtered", "essm", "essm-table1", "essm-table2", "ssm", "ssm-table1", "ssm-table2", "pareto")


def device_facts(device: str) -> dict:
    import warp as wp

    from wsoft.parallel import init_warp

    init_warp()
    d = wp.get_device(device)
    facts = {"device": device, "name": d.name, "warp": wp.__version__, "python": platform.python_version(),
             "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()}
    if d.is_cuda:
        facts |= {"arch": f"sm_{d.arch}", "memory_gib": round(d.total_memory / 2**30, 1), "sm_count": getattr(d, "sm_count", None)}
    return facts


def run_tests(device: str, timeout_s: float) -> dict:
    """The test suite with ``device`` as the tests' device (``WSOFT_TEST_DEVICES``); outcome and time."""
    root = Path(__file__).resolve().parents[1]
    if not (root / "tests").is_dir():
        return {"rc": None, "summary": "no tests folder next to the package (installed without the sources: run from a clone)",
                "seconds": 0.0, "failures": []}
    env = dict(os.environ, WSOFT_TEST_DEVICES=device)
    t0 = time.time()
    try:
        p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(root / "tests")], cwd=root, env=env,
                           capture_output=True, text=True, timeout=max(timeout_s, 1))
        tail = (p.stdout + p.stderr).strip().splitlines()
        return {"rc": p.returncode, "summary": tail[-1] if tail else "", "seconds": round(time.time() - t0, 1),
                "failures": [ln for ln in tail if ln.startswith(("FAILED", "ERROR"))][:30]}
    except subprocess.TimeoutExpired:
        return {"rc": None, "summary": f"stopped after {timeout_s:.0f} s", "seconds": round(time.time() - t0, 1), "failures": []}


def row_ms(row: dict) -> float | None:
    """A row's headline time: a frame's total, a build, a stage sum, or a graph's ground truth."""
    t = row.get("timings_ms")
    if isinstance(t, dict) and "total" in t:
        return float(t["total"])
    for k in ("build_ms", "new_ms", "raster_ms", "warp_pass_ms"):
        if isinstance(row.get(k), (int, float)):
            return float(row[k])
    if isinstance(row.get("stages_ms"), dict):
        return float(sum(v for v in row["stages_ms"].values() if isinstance(v, (int, float))))
    if isinstance(row.get("entries"), list):  # pareto: every entry's frame time
        return float(sum(e.get("frame_ms", 0.0) for e in row["entries"] if isinstance(e, dict)))
    return None


def compare_rows(rows: list[dict], device: str) -> list[tuple[str, float | None, float | None]]:
    """(row, CPU ms, device ms) for the rows run on both."""
    by: dict[str, dict[str, float | None]] = {}
    for r in rows:
        case = dict(r.get("case", {}))
        dev = case.pop("device", "cpu")
        key = json.dumps(case, sort_keys=True)
        by.setdefault(key, {})[dev] = row_ms(r)
    out = []
    for key, d in by.items():
        case = json.loads(key)
        parts = []
        for k, v in case.items():
            if k in ("width", "height", "ref_samples", "quick", "image") or v in (None, False):
                continue
            parts.append(" ".join(f"{pk}={pv}" for pk, pv in v.items()) if isinstance(v, dict) else str(v))
        out.append((" ".join(parts)[:110], d.get("cpu"), d.get(device)))
    return out


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wsoft.gpu_check", description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda:0", help="the device to check (default: cuda:0)")
    ap.add_argument("--out-dir", default="reports", help="where gpu-check.md goes (default: ./reports)")
    ap.add_argument("--budget-s", type=float, default=540.0, help="stop before a step that would start past this many seconds")
    ap.add_argument("--skip-tests", action="store_true", help="only the quick sweeps")
    ap.add_argument("--sweeps", default=",".join(QUICK_SWEEPS), help="comma-separated quick sweeps to run")
    args = ap.parse_args(argv)

    from wsoft.bench.harness import SWEEPS, read_rows, run_sweep
    from wsoft.errors import WsoftError

    t_start = time.time()
    left = lambda: args.budget_s - (time.time() - t_start)  # noqa: E731
    try:
        facts = device_facts(args.device)
    except Exception as exc:  # noqa: BLE001 - no such device: say so in one line
        print(f"wsoft.gpu_check: error: device {args.device!r} is not available ({' '.join(str(exc).split())})", file=sys.stderr)
        return 2
    print(f"gpu_check on {facts['device']} ({facts['name']}), budget {args.budget_s:.0f} s", file=sys.stderr)
    tests = None
    if not args.skip_tests:
        tests = run_tests(args.device, timeout_s=0.5 * left())
        print(f"tests: {tests['summary']} ({tests['seconds']} s)", file=sys.stderr)
    sweeps = [s for s in args.sweeps.split(",") if s]
    unknown = [s for s in sweeps if s not in SWEEPS]
    if unknown:
        print(f"wsoft.gpu_check: error: unknown sweeps {', '.join(unknown)}; sweeps: {', '.join(sorted(SWEEPS))}", file=sys.stderr)
        return 2
    devices = [args.device] if args.device == "cpu" else [args.device, "cpu"]
    done, skipped, seconds = {}, [], {}
    with tempfile.TemporaryDirectory() as work:
        for s in sweeps:
            if left() <= 0:
                skipped.append(s)
                continue
            t0 = time.time()
            try:
                run_sweep(s, quick=True, device=devices, out_dir=work, fresh=True)
            except WsoftError as exc:
                print(f"sweep {s}: {exc.line()}", file=sys.stderr)
            seconds[s] = round(time.time() - t0, 1)
            done[s] = read_rows(Path(work) / f"{s}-quick.jsonl")
    total = round(time.time() - t_start, 1)
    lines = [f"# GPU check on {facts['device']}", "",
             f"Command: `python -m wsoft.gpu_check{'' if args.device == 'cuda:0' else ' --device ' + args.device}"
             f"{' --skip-tests' if args.skip_tests else ''}` — {total} s in all (budget {args.budget_s:.0f} s).", "",
             "| fact | value |", "|---|---|", *[f"| {k} | {v} |" for k, v in facts.items()], ""]
    if tests is not None:
        lines += ["## Tests", "", f"`WSOFT_TEST_DEVICES={args.device} pytest`: {tests['summary']} in {tests['seconds']} s "
                  f"(exit {tests['rc']}).", "", *[f"* {f}" for f in tests["failures"]], ""]
    lines += ["## Quick sweeps", "", f"Each quick sweep ran on {' and '.join(devices)} in one process; times in ms "
              "(a frame's total, a structure's build, or the sum of a row's stages).", ""]
    for s, rows in done.items():
        if args.device == "cpu":
            lines += [f"### {s} ({seconds[s]} s)", "", "| row | cpu ms |", "|---|---:|"]
            lines += [f"| {label} | {_ms(c)} |" for label, c, _ in compare_rows(rows, "cpu")]
        else:
            lines += [f"### {s} ({seconds[s]} s)", "", f"| row | cpu ms | {args.device} ms | speed-up |", "|---|---:|---:|---:|"]
            for label, c, g in compare_rows(rows, args.device):
                lines.append(f"| {label} | {_ms(c)} | {_ms(g)} | {f'{c / g:.1f}x' if c and g else '-'} |")
        lines.append("")
    if skipped:
        lines += [f"Not run (over the budget): {', '.join(skipped)}.", ""]
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "gpu-check.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'gpu-check.md'} ({total} s)", file=sys.stderr)
    return 0 if (tests is None or tests["rc"] == 0) and not skipped else 1


if __name__ == "__main__":
    sys.exit(main())
