"""The regression gate: compare a sweep's rows with a saved baseline, row by row, metric by metric.

``wsoft regress OLD NEW`` (:func:`main`) and ``wsoft bench SWEEP --baseline NAME|PATH`` compare
rows that share their ``key``; each row flattens to named metrics
(:func:`wsoft.bench.regress_rows.flatten`): per-round times judged by ratio and a Mann-Whitney U
test, error metrics judged against a floor and the rows' standard errors
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
import sys
from dataclasses import dataclass, field
from pathlib import Path

from wsoft.bench.regress_rows import Source, check_name, describe, flatten, machine_of, other_machine, pairs, resolve, rows_of, save
from wsoft.bench.regress_stats import FLOORS, TIME_THRESHOLD, Z, Verdict, accuracy_verdict, count_verdict, time_verdict


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
        import statistics

        xs = [v for v in x if v == v]
        return f"{statistics.median(xs):.2f} ms (med of {len(x)})" if xs else "-"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def compare_rows(old: dict[str, dict], new: dict[str, dict], *, stem: str = "", fp_old: dict | None = None, fp_new: dict | None = None,
                 time_threshold: float = TIME_THRESHOLD) -> Comparison:
    """Compare rows by key (``old`` and ``new``: key -> row)."""
    out = Comparison(stem, len(old), len(new))
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
        same = 0
        for name, a in mo.items():
            b = mn.get(name)
            if b is None or b.kind != a.kind:
                out.findings.append(Finding(what, name, _show(a.samples or a.value), "missing", Verdict("worse", "metric vanished")))
                continue
            if a.kind == "time":
                if why:
                    continue
                v = time_verdict(a.samples, b.samples, time_threshold)
                shown = (_show(a.samples), _show(b.samples))
            elif a.kind == "accuracy":
                v = accuracy_verdict(a.value, b.value, a.se, b.se, FLOORS.get(name.rsplit(".", 1)[-1].split("#")[0], 0.0))
                shown = (_show(a.value), _show(b.value))
            else:
                v = count_verdict(a.value, b.value)
                shown = (_show(a.value), _show(b.value))
            if v.kind in ("worse", "better"):
                out.findings.append(Finding(what, name, *shown, v))
            else:
                same += 1
        out.unchanged[what] = same
    out.added = [describe(r) for k, r in new.items() if k not in old]
    for side, rows in (("old", old), ("new", new)):
        out.loads[side] = [float(r["machine"]["load"]) for r in rows.values() if (r.get("machine") or {}).get("load") is not None]
        out.cores |= {r["machine"]["cores"] for r in rows.values() if (r.get("machine") or {}).get("cores")}
    return out


def compare(old: Source, new: Source, time_threshold: float = TIME_THRESHOLD) -> list[Comparison]:
    """Compare every rows file the two sources share (:func:`~wsoft.bench.regress_rows.pairs`)."""
    return [compare_rows(rows_of(fo), rows_of(fn), stem=stem, fp_old=old.fingerprint, fp_new=new.fingerprint, time_threshold=time_threshold)
            for stem, fo, fn in pairs(old, new)]


def report(results: list[Comparison], old: str, new: str, time_threshold: float = TIME_THRESHOLD) -> str:
    """The markdown report of :func:`compare`'s results."""
    L = [f"# Regression gate: `{new}` against `{old}`", ""]
    L.append(f"Time: ratio of medians new/old over the per-round times; a slowdown counts beyond x{1 + time_threshold:.2f} when a one-sided "
             "Mann-Whitney U test rejects at 0.05 (with too few rounds for the test: the fastest new round beyond the slowest old one "
             f"x{1 + time_threshold:.2f}). Accuracy: a change counts beyond max(floor, {Z:g} x sqrt(se_old^2 + se_new^2)), floors "
             + ", ".join(f"{k} {v:g}" for k, v in FLOORS.items()) + "; a vanished row or metric, or a new NaN, is a regression.")
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


def gate_kwargs(args) -> dict:
    """:func:`~wsoft.bench.harness.run_sweep`'s gate arguments from :func:`add_gate_arguments`' options."""
    return {"save": args.save, "baseline": args.baseline, "time_threshold": args.time_threshold}


def check_threshold(t: float) -> None:
    from wsoft.errors import ParameterError

    if not (t == t and (0.0 <= t < 10.0 or t == float("inf"))):
        raise ParameterError(f"--time-threshold {t}: give a fraction in [0, 10) (0.10: 10 % slower), or inf to judge no time")


def before_sweep(save_name: str | None, baseline: str | None, out_dir: str | Path, time_threshold: float) -> Source | None:
    """Check the gate's options before a sweep runs: the baseline exists, the name is a name."""
    check_threshold(time_threshold)
    if save_name is not None:
        check_name(save_name)
    return resolve(baseline, out_dir, "--baseline") if baseline else None


def after_sweep(stem: str, jsonl: Path, keys: set[str], out_dir: str | Path, save_name: str | None, baseline: Source | None,
                time_threshold: float) -> int:
    """After a sweep: compare its rows (those of ``keys`` in ``jsonl``) with ``baseline``, writing
    ``<out_dir>/<stem>-regress.md`` and printing it, then save them as ``save_name`` unless they
    regressed; 1 on a regression."""
    from wsoft.bench.regress_rows import fingerprint

    new = {k: r for k, r in rows_of(jsonl).items() if k in keys}
    rc = 0
    if baseline is not None:
        base = baseline.files.get(stem) or (next(iter(baseline.files.values())) if len(baseline.files) == 1 else None)
        if base is None:
            from wsoft.errors import ParameterError

            raise ParameterError(f"--baseline {baseline.given}: holds no {stem}.jsonl (it holds {', '.join(baseline.files)})")
        results = [compare_rows(rows_of(base), new, stem=stem, fp_old=baseline.fingerprint, fp_new=fingerprint(), time_threshold=time_threshold)]
        text = report(results, baseline.given, str(jsonl), time_threshold)
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
    p.add_argument("--output", metavar="FILE.md", help="also write the report there")


def run(args) -> int:
    """``wsoft regress`` on parsed arguments (:func:`parser`); errors raise :class:`~wsoft.errors.WsoftError`."""
    check_threshold(args.time_threshold)
    old, new = resolve(args.old, args.out_dir), resolve(args.new, args.out_dir)
    results = compare(old, new, args.time_threshold)
    text = report(results, args.old, args.new, args.time_threshold)
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
