"""``wsoft regress OLD NEW``: two runs of a sweep compared row by row (:mod:`wsoft.bench.regress`); exit 1 on a regression."""

from __future__ import annotations

import wsoft.cli.args as a


def add_parser(sub, one_of: str) -> None:
    from wsoft.bench.regress import add_arguments

    r = sub.add_parser("regress", help="compare two runs of a sweep (time by a rank test over rounds, errors beyond noise); exit 1 on "
                       "a regression (docs/ci.md)", formatter_class=a.Help)
    add_arguments(r)
    r.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.bench.regress import run as compare_runs

    return compare_runs(args)
