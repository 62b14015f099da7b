"""``wsoft report SWEEP``: a sweep's rows as ``<out-dir>/<sweep>.html``, a page to explore offline
(:mod:`wsoft.bench.html_page`: per scene and light the error against time with hover and click to
the point's images, technique families to hide, the 'Which technique to use' table linked to its
points), and with ``--baseline ROWS`` a page of the rows against an earlier run's
(``<sweep>-baseline.html``, :mod:`wsoft.bench.html_baseline`). Rows of any sweep: those holding
``entries`` per scene and light, those measuring one setting each, and any other (a table)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def write_html(sweep: str, rows: list[dict], out_dir, baseline_rows: list[dict] | None = None) -> Path:
    """Write ``out_dir/<sweep>.html`` from ``rows`` (``sweep``: the report's stem, as its ``.jsonl``
    and ``.md`` are named, ``pareto`` or ``pareto-quick``; its images lie under ``images/<sweep>/``),
    and with ``baseline_rows`` also ``out_dir/<sweep>-baseline.html``; returns the first's path."""
    from wsoft.bench import html_baseline, html_page
    from wsoft.bench.html_rows import groups

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{sweep}.html"
    href = None
    if baseline_rows is not None:
        cmp_path = out / f"{sweep}-baseline.html"
        cmp_path.write_text(html_baseline.page(sweep, rows, baseline_rows, out, sweep, path.name), encoding="utf-8")
        href = cmp_path.name
    path.write_text(html_page.page(sweep, groups(rows, out, sweep), rows, baseline_href=href), encoding="utf-8")
    return path


def rows_file(sweep: str, out_dir: Path, quick: bool) -> tuple[str, Path]:
    """The report's stem and rows file of ``sweep``: a rows file of that name in ``out_dir``
    (``pareto-quick``), else the sweep's report (a sweep module may name it otherwise)."""
    import importlib

    from wsoft.bench.harness import SWEEPS, sweep_name

    if not quick and (out_dir / f"{sweep}.jsonl").is_file():
        return sweep, out_dir / f"{sweep}.jsonl"
    name = sweep_name(sweep)
    stem = getattr(importlib.import_module(SWEEPS[name]), "REPORT", name)
    stem = f"{stem}-quick" if quick else stem
    return stem, out_dir / f"{stem}.jsonl"


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """``wsoft report``'s arguments (the command line's parser and :func:`main` share them)."""
    ap.add_argument("sweep", help="the sweep (pareto, temporal, filtered, ...) or a rows file's stem in --out-dir (pareto-quick)")
    ap.add_argument("--out-dir", default="reports", help="the folder of the rows, their images and the page (default: reports)")
    ap.add_argument("--quick", action="store_true", help="the quick mode's rows (<sweep>-quick.jsonl)")
    ap.add_argument("--baseline", metavar="ROWS", help="an earlier run's rows (a .jsonl file, or a folder holding <sweep>.jsonl): "
                    "also write <sweep>-baseline.html, old against new per setting")


def run(a) -> int:
    """``wsoft report`` on parsed arguments; bad input raises :class:`~wsoft.errors.ParameterError`."""
    from wsoft.bench.harness import finished_rows
    from wsoft.errors import ParameterError

    out = Path(a.out_dir)
    stem, jsonl = rows_file(a.sweep, out, a.quick)
    if not jsonl.is_file():
        raise ParameterError(f"no rows file {jsonl} (run `wsoft bench {a.sweep}{' --quick' if a.quick else ''}` first)")
    baseline = None
    if a.baseline:
        b = Path(a.baseline)
        b = b / jsonl.name if b.is_dir() else b
        if not b.is_file():
            raise ParameterError(f"--baseline {a.baseline}: no baseline rows file {b}")
        baseline = finished_rows(b)
    path = write_html(stem, finished_rows(jsonl), out, baseline)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)" + (f" and {path.with_name(f'{stem}-baseline.html')}" if baseline is not None else ""),
          file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``wsoft report SWEEP [--out-dir DIR] [--quick] [--baseline ROWS]``: 0 when the page is written, 2 on bad input."""
    from wsoft.errors import WsoftError

    ap = argparse.ArgumentParser(prog="wsoft report", description="Write a sweep's rows as a page to explore offline: <out-dir>/<sweep>.html.")
    add_arguments(ap)
    try:
        return run(ap.parse_args(argv))
    except WsoftError as exc:
        print(f"wsoft: error: {exc.line()}", file=sys.stderr)
        return 2
