"""``wsoft calibrate``: ``--technique auto``'s model rebuilt from sweep rows, or scaled by a quick
measurement."""

from __future__ import annotations

import os

import wsoft.cli.args as a
from wsoft.cli.common import check_device, check_output


def add_parser(sub, one_of: str) -> None:
    k = sub.add_parser("calibrate", help="rebuild --technique auto's model from your own sweep rows, or scale it by a quick measurement",
                       formatter_class=a.Help, description="From sweep rows (--rows: wsoft bench pareto's on this machine; their "
                       "features computed, or read from --features, wsoft bench auto's rows): both predictors compared scene by scene "
                       "held out, each quantity by the closer, fitted to every frame. --quick: no sweep, the model's times scaled by "
                       "measured over predicted times of a few settings on a small bundled frame.")
    k.add_argument("--rows", metavar="JSONL", help="a pareto sweep's rows (reports/pareto.jsonl)")
    k.add_argument("--features", metavar="JSONL", help="their features (reports/auto.jsonl; those it lacks are computed)")
    k.add_argument("--temporal", metavar="JSONL", help="wsoft bench temporal's rows (reports/temporal.jsonl): the flicker model")
    k.add_argument("--modern", metavar="JSONL", help="wsoft bench modern's rows (reports/modern.jsonl): entries the pareto row of the same "
                   "frame lacks are added")
    k.add_argument("--quick", action="store_true", help="scale the model's times by a quick measurement instead")
    a.device(k, "the device to calibrate for (default: the default device)")
    k.add_argument("--out", metavar="JSON", help="where to write the model (default: the package's model of the device kind)")
    k.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.auto.calibrate import calibrate
    from wsoft.errors import ParameterError
    from wsoft.parallel import resolve_device

    if args.quick and args.rows:
        raise ParameterError("calibrate: --quick or --rows, one of the two")
    if args.quick and (args.temporal or args.modern):
        raise ParameterError("calibrate: --temporal and --modern go with --rows, not --quick")
    for path, what in ((args.rows, "--rows"), (args.features, "--features"), (args.temporal, "--temporal"), (args.modern, "--modern")):
        if path and not os.path.isfile(path):
            raise ParameterError(f"{what} {path}: no such file")
    check_device(args.device)
    if args.out:
        check_output(args.out, "--out")
    dest, what = calibrate(rows=args.rows, features=args.features, quick=args.quick, device=resolve_device(args.device), out=args.out,
                           temporal=args.temporal, modern=args.modern)
    print(f"wrote {dest}: {what}")
    return 0
