"""The regression gate: compare a sweep's rows with a saved baseline, row by row, metric by metric.

``wsoft regress OLD NEW`` (:func:`main`) and ``wsoft bench SWEEP --baseline NAME|PATH`` compare
rows that share their ``key``; each row flattens to named metrics
(:func:`wsoft.bench.regress_rows.flatten`): per-round times judged by ratio and a Mann-Whitney U
test at a Šidák-corrected level over the run's time comparisons, error metrics judged against a floor and the rows' standard errors
(:mod:`wsoft.bench.regress_stats` states both tests). A row of the baseline missing from the new
rows, a metric that vanished or turned NaN are regressions. Rows timed on another machine (host,
Warp's CPU threads or CPU model differ) are compared for accuracy only, and the report says so.
``wsoft bench SWEEP --save NAME`` keeps a run's rows as baseline NAME
(``<out-dir>/baselines/NAME/<sweep>.jsonl`` and ``fingerprint.json``).

The report is a markdown table of regressions, improvements and unchanged rows, printed (and
written to ``<out-dir>/<sweep>-regress.md`` by ``wsoft bench``); exit code 1 on any regression.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path

from wsoft.bench.regress_rounds import DEFAULT_TIMER, HOST_NOMINAL_MS, ROUNDS, TIMERS, judged_time
from wsoft.bench.regress_rows import Source, check_name, describe, flatten, machine_of, other_machine, pairs, resolve, rows_of, save
from wsoft.bench.regress_stats import ALPHA, FLOORS, TIME_THRESHOLD, Z, Verdict, accuracy_verdict, count_verdict, sidak, time_verdict


@dataclass
class Finding:
    row: str  # the row in a few words
    metric: str
    old: str
    new: str
    verdict: Verdict


@dataclass
class Comparison:
    """The outcome of comparing one rows file with another."""

    stem: str
    old_rows: int = 0
    new_rows: int = 0
    findings: list[Finding] = field(default_factory=list)
    unchanged: dict[str, int] = field(default_factory=dict)  # row -> metrics judged unchanged
    time_not_judged: dict[str, str] = field(default_factory=dict)  # row -> why (another machine)
    added: list[str] = field(default_factory=list)  # rows only the new side has
    loads: dict[str, list[float]] = field(default_factory=dict)  # "old"/"new" -> the host's 1-minute load as each row finished
    cores: set = field(default_factory=set)
    time_comparisons: int = 0  # the time metrics judged: the Šidák correction's k
    time_level: float = ALPHA  # each time comparison's level, sidak(ALPHA, time_comparisons)
    few_rounds: list[Finding] = field(default_factory=list)  # time metrics whose rounds cannot reach time_level
    time_ratios: list[float] = field(default_factory=list)  # every judged time metric's ratio of medians new/old

    @property
    def regressions(self) -> list[Finding]:
        return [f for f in self.findings if f.verdict.kind == "worse"]

    @property
    def improvements(self) -> list[Finding]:
        return [f for f in self.findings if f.verdict.kind == "better"]


def _show(x) -> str:
    if x is None:
        return "-"
    if isinstance(x, list):
        xs = [v for v in x if v == v]
        return f"{statistics.median(xs):.2f} ms (med of {len(x)})" if xs else "-"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def _record(out: Comparison, f: Finding) -> None:
    if f.verdict.ratio is not None and math.isfinite(f.verdict.ratio):
        out.time_ratios.append(f.verdict.ratio)
    if f.verdict.kind in ("worse", "better"):
        out.findings.append(f)
    elif f.verdict.kind == "too few rounds":
        out.few_rounds.append(f)
    else:
        out.unchanged[f.row] += 1


def compare_rows(old: dict[str, dict], new: dict[str, dict], *, stem: str = "", fp_old: dict | None = None, fp_new: dict | None = None,
                 time_threshold: float = TIME_THRESHOLD, timer: str = DEFAULT_TIMER) -> Comparison:
    """Compare rows by key (``old`` and ``new``: key -> row); ``timer``: which of the gate's timed
    rounds are judged (:func:`~wsoft.bench.regress_rounds.judged_time`)."""
    out = Comparison(stem, len(old), len(new))
    timed: list[tuple[str, str, object, object]] = []  # (row, metric, old, new): judged once their number is known
    for key, ro in old.items():
        what = describe(ro)
        rn = new.get(key)
        if rn is None:
            out.findings.append(Finding(what, "(row)", "present", "missing", Verdict("worse", "row vanished")))
            continue
        why = other_machine(machine_of(ro, fp_old), machine_of(rn, fp_new))
        if why:
            out.time_not_judged[what] = why
        mo, mn = flatten(ro), flatten(rn)
        out.unchanged.setdefault(what, 0)
        for name, a in mo.items():
            b = mn.get(name)
            if b is None or b.kind != a.kind:
                out.findings.append(Finding(what, name, _show(a.samples or a.value), "missing", Verdict("worse", "metric vanished")))
                continue
            if a.kind == "time":
                if not why and judged_time(name, mo, timer):
                    timed.append((what, name, a, b))
                continue
            if a.kind == "accuracy":
                v = accuracy_verdict(a.value, b.value, a.se, b.se, FLOORS.get(name.rsplit(".", 1)[-1].split("#")[0], 0.0))
            else:
                v = count_verdict(a.value, b.value)
            _record(out, Finding(what, name, _show(a.value), _show(b.value), v))
    out.time_comparisons = len(timed)
    out.time_level = sidak(ALPHA, len(timed))
    for what, name, a, b in timed:
        _record(out, Finding(what, name, _show(a.samples), _show(b.samples), time_verdict(a.samples, b.samples, time_threshold, out.time_level)))
    out.added = [describe(r) for k, r in new.items() if k not in old]
    for side, rows in (("old", old), ("new", new)):
        out.loads[side] = [float(r["machine"]["load"]) for r in rows.values() if (r.get("machine") or {}).get("load") is not None]
        out.cores |= {r["machine"]["cores"] for r in rows.values() if (r.get("machine") or {}).get("cores")}
    return out


def compare(old: Source, new: Source, time_threshold: float = TIME_THRESHOLD, timer: str = DEFAULT_TIMER) -> list[Comparison]:
    """Compare every rows file the two sources share (:func:`~wsoft.bench.regress_rows.pairs`)."""
    return [compare_rows(rows_of(fo), rows_of(fn), stem=stem, fp_old=old.fingerprint, fp_new=new.fingerprint, time_threshold=time_threshold,
                         timer=timer) for stem, fo, fn in pairs(old, new)]


TIMER_TEXT = {"cpu": "CPU time, every thread of the process", "wall": "wall clock",
              "host": f"CPU time over the host workload's just before it, in {HOST_NOMINAL_MS:g} ms host units"}


def report(results: list[Comparison], old: str, new: str, time_threshold: float = TIME_THRESHOLD, timer: str = DEFAULT_TIMER) -> str:
    """The markdown report of :func:`compare`'s results."""
    L = [f"# Regression gate: `{new}` against `{old}`", ""]
    L.append(f"Time ({TIMER_TEXT.get(timer, timer)} of the gate's timed rounds, "
             f"where the rows have them): ratio of medians new/old over the per-round times; a change counts beyond x{1 + time_threshold:.2f} (or below "
             f"x{1 / (1 + time_threshold):.2f}) when a two-sided Mann-Whitney U test over the rounds also rejects, at a level Šidák-corrected "
             f"for the run's time comparisons (any false alarm in a run: {ALPHA:g}). Accuracy: a change counts beyond max(floor, {Z:g} x "
             "sqrt(se_old^2 + se_new^2)), floors " + ", ".join(f"{k} {v:g}" for k, v in FLOORS.items())
             + "; a vanished row or metric, or a new NaN, is a regression.")
    for c in results:
        reg, imp = c.regressions, c.improvements
        L += ["", f"## `{c.stem}`: {len(reg)} regressions, {len(imp)} improvements ({c.old_rows} rows before, {c.new_rows} now)", ""]
        if any(c.loads.values()):
            L.append("Host load (1-minute average) as the rows finished: " + "; ".join(
                f"{side} {min(v):.1f}-{max(v):.1f}" for side, v in c.loads.items() if v)
                + (f" on {'/'.join(map(str, sorted(c.cores)))} cores" if c.cores else "")
                + ": a load above the cores stretches times from run to run, beyond what the rounds of one run show.")
            L.append("")
        if time_threshold == float("inf"):
            L += ["**Times not judged** (`--time-threshold inf`): accuracy only.", ""]
        if c.time_comparisons and time_threshold != float("inf"):
            L.append(f"{c.time_comparisons} time comparisons, each U test at level {c.time_level:.3g}.")
            whole = statistics.median(c.time_ratios) if len(c.time_ratios) >= 3 else 1.0
            if not 1 / (1 + time_threshold) <= whole <= 1 + time_threshold:
                L.append(f"The run's time metrics moved together: their median ratio is x{whole:.2f}, a change of the host (its load, "
                         "clocks or another job's use of shared caches) or one shared by every row; rerun both sides on a host that runs "
                         "nothing else before reading a time verdict.")
            L.append("")
        if c.few_rounds:
            L += [f"**Times not judged: too few rounds** for {len(c.few_rounds)} of {c.time_comparisons} time metrics: their rounds can never "
                  f"reach the level {c.time_level:.3g} (two-sided, every new round beyond every old one gives 2 / C(m + n, m)); rerun both sides "
                  "with more rounds (`wsoft bench --rounds 16`). Beyond the threshold but not judged:", ""]
            beyond = [f for f in c.few_rounds if _beyond(f.verdict, time_threshold)]
            L += [f"- {f.row} {f.metric}: {f.old} -> {f.new}, {f.verdict.how}" for f in beyond] or ["- none"]
            L.append("")
        if c.time_not_judged:
            whys = sorted(set(c.time_not_judged.values()))
            L.append(f"**Times not judged** for {len(c.time_not_judged)} rows measured on another machine ({'; '.join(whys)}): "
                     "those rows are compared for accuracy only.")
            L.append("")
        for title, rows in (("Regressions", reg), ("Improvements", imp)):
            if not rows:
                continue
            L += [f"### {title}", "", "| row | metric | old | new | test |", "|---|---|---|---|---|"]
            L += [f"| {f.row} | {f.metric} | {f.old} | {f.new} | {f.verdict.how} |" for f in rows]
            L.append("")
        changed = {f.row for f in c.findings}
        quiet = [(r, n) for r, n in c.unchanged.items() if r not in changed]
        if quiet:
            L += ["### Unchanged", "", "| row | metrics unchanged |", "|---|---|"]
            L += [f"| {r} | {n} |" for r, n in quiet]
            L.append("")
        if c.added:
            L.append(f"New rows (no baseline to compare): {', '.join(c.added)}.")
    return "\n".join(L).rstrip() + "\n"


def _beyond(v: Verdict, threshold: float) -> bool:
    """Whether a time verdict's ratio lies beyond the threshold either way."""
    return v.ratio is not None and (v.ratio > 1 + threshold or v.ratio < 1 / (1 + threshold))


def failed(results: list[Comparison]) -> bool:
    return any(c.regressions for c in results)


# -- command line and the bench hook --------------------------------------------------------------


def add_gate_arguments(parser: argparse.ArgumentParser) -> None:
    """``wsoft bench``'s gate options: ``--save NAME``, ``--baseline NAME|PATH``, ``--time-threshold``."""
    parser.add_argument("--save", metavar="NAME", help="keep this run's rows as baseline NAME (<out-dir>/baselines/NAME/)")
    parser.add_argument("--baseline", metavar="NAME|PATH", help="compare this run's rows with a baseline (a saved name, a baseline folder or "
                        "a .jsonl rows file); exit 1 on a regression, report in <out-dir>/<sweep>-regress.md")
    parser.add_argument("--time-threshold", type=float, default=TIME_THRESHOLD, metavar="F",
                        help=f"a slowdown counts beyond 1+F times the baseline (default {TIME_THRESHOLD}; inf: judge no time)")
    parser.add_argument("--rounds", type=int, default=ROUNDS, metavar="N",
                        help=f"with --save or --baseline: time every render row N more times after the sweep, round by round across the "
                        f"rows in alternating order, for the gate's rank test (default {ROUNDS}; 0: the sweep's own 3 rounds, too few "
                        "for the test)")
    parser.add_argument("--timer", choices=TIMERS, default=DEFAULT_TIMER, help="which time of the timed rounds the gate judges: host (the "
                        "process's CPU time over a fixed host workload's, timed before each round; default), cpu (the CPU time alone, "
                        "what other jobs on the host add least to) or wall (the wall clock: on a runner that runs nothing else)")


def gate_kwargs(args) -> dict:
    """:func:`~wsoft.bench.harness.run_sweep`'s gate arguments from :func:`add_gate_arguments`' options."""
    return {"save": args.save, "baseline": args.baseline, "time_threshold": args.time_threshold, "rounds": args.rounds,
            "timer": args.timer}


def check_rounds(n: int) -> None:
    from wsoft.errors import ParameterError

    if not 0 <= n <= 1000:
        raise ParameterError(f"--rounds {n}: give a number of rounds in [0, 1000] ({ROUNDS}: the default)")


def check_threshold(t: float) -> None:
    from wsoft.errors import ParameterError

    if not (t == t and (0.0 <= t < 10.0 or t == float("inf"))):
        raise ParameterError(f"--time-threshold {t}: give a fraction in [0, 10) (0.10: 10 % slower), or inf to judge no time")


def before_sweep(save_name: str | None, baseline: str | None, out_dir: str | Path, time_threshold: float, rounds: int = ROUNDS) -> Source | None:
    """Check the gate's options before a sweep runs: the baseline exists, the name is a name."""
    check_threshold(time_threshold)
    check_rounds(rounds)
    if save_name is not None:
        check_name(save_name)
    return resolve(baseline, out_dir, "--baseline") if baseline else None


def after_sweep(stem: str, jsonl: Path, keys: set[str], out_dir: str | Path, save_name: str | None, baseline: Source | None,
                time_threshold: float, rounds: int = ROUNDS, timer: str = DEFAULT_TIMER) -> int:
    """After a sweep: time its render rows ``rounds`` more times (:func:`~wsoft.bench.regress_rounds.time_rounds`),
    compare its rows (those of ``keys`` in ``jsonl``) with ``baseline``, writing
    ``<out_dir>/<stem>-regress.md`` and printing it, then save them as ``save_name`` unless they
    regressed; 1 on a regression."""
    from wsoft.bench.regress_rounds import time_rounds
    from wsoft.bench.regress_rows import fingerprint

    if not (baseline is None and save_name is None) and time_threshold != float("inf"):
        time_rounds(Path(jsonl), keys, rounds)
    new = {k: r for k, r in rows_of(jsonl).items() if k in keys}
    rc = 0
    if baseline is not None:
        base = baseline.files.get(stem) or (next(iter(baseline.files.values())) if len(baseline.files) == 1 else None)
        if base is None:
            from wsoft.errors import ParameterError

            raise ParameterError(f"--baseline {baseline.given}: holds no {stem}.jsonl (it holds {', '.join(baseline.files)})")
        results = [compare_rows(rows_of(base), new, stem=stem, fp_old=baseline.fingerprint, fp_new=fingerprint(), time_threshold=time_threshold,
                                   timer=timer)]
        text = report(results, baseline.given, str(jsonl), time_threshold, timer)
        md = Path(out_dir) / f"{stem}-regress.md"
        md.write_text(text)
        print(text)
        print(f"wrote {md}: {'REGRESSION' if failed(results) else 'no regression'}", file=sys.stderr)
        rc = 1 if failed(results) else 0
    if save_name and rc:
        print(f"baseline {save_name!r} kept as it was: this run regressed (to accept it, rerun with --save alone)", file=sys.stderr)
    elif save_name:
        d = save(save_name, stem, list(new.values()), out_dir)
        print(f"saved baseline {save_name!r} in {d} ({len(new)} rows)", file=sys.stderr)
    return rc


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wsoft regress", description="Compare two runs of a sweep; exit 1 on a regression.")
    add_arguments(p)
    return p


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``wsoft regress``'s arguments (the command line's parser and :func:`parser` share them)."""
    p.add_argument("old", help="the baseline: a saved baseline's name, a baseline folder or a .jsonl rows file")
    p.add_argument("new", help="the run to judge, given the same ways")
    p.add_argument("--out-dir", default="reports", help="where saved baselines are looked up by name (<out-dir>/baselines/NAME; default ./reports)")
    p.add_argument("--time-threshold", type=float, default=TIME_THRESHOLD, metavar="F",
                   help=f"a slowdown counts beyond 1+F times the baseline (default {TIME_THRESHOLD}; inf: judge no time)")
    p.add_argument("--timer", choices=TIMERS, default=DEFAULT_TIMER, help="which time of the gate's timed rounds to judge: host (default), cpu or wall")
    p.add_argument("--output", metavar="FILE.md", help="also write the report there")


def run(args) -> int:
    """``wsoft regress`` on parsed arguments (:func:`parser`); errors raise :class:`~wsoft.errors.WsoftError`."""
    check_threshold(args.time_threshold)
    old, new = resolve(args.old, args.out_dir), resolve(args.new, args.out_dir)
    results = compare(old, new, args.time_threshold, args.timer)
    text = report(results, args.old, args.new, args.time_threshold, args.timer)
    print(text, end="")
    if args.output:
        Path(args.output).write_text(text)
    return 1 if failed(results) else 0


def main(argv: list[str] | None = None) -> int:
    """``wsoft regress OLD NEW [...]``: 0 no regression, 1 a regression, 2 bad input (one line)."""
    from wsoft.errors import WsoftError

    args = parser().parse_args(argv)
    try:
        return run(args)
    except WsoftError as exc:
        print(f"wsoft: error: {exc.line()}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"wsoft: error: {getattr(exc, 'filename', None) or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
