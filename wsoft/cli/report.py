"""``wsoft report SWEEP``: a sweep's rows as a page to explore offline (:mod:`wsoft.bench.html_report`)."""

from __future__ import annotations

import wsoft.cli.args as a


def add_parser(sub, one_of: str) -> None:
    from wsoft.bench.html_report import add_arguments

    r = sub.add_parser("report", help="write <out-dir>/<sweep>.html from a sweep's rows: error against time with hover, the frames "
                       "behind a point, the which-technique table, a baseline page", formatter_class=a.Help)
    add_arguments(r)
    r.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.bench.html_report import run as write_page

    return write_page(args)
