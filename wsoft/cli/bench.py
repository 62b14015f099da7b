"""``wsoft bench``: a benchmark sweep (:mod:`wsoft.bench.harness`), locally or on a Dask cluster."""

from __future__ import annotations

import wsoft.cli.args as a
from wsoft.cli.common import check_device, check_output
from wsoft.cli.progress import CompileNotice


def sweeps() -> dict:
    """The harness's sweeps (:data:`wsoft.bench.harness.SWEEPS`; names only, no sweep imported)."""
    from wsoft.bench.harness import SWEEPS

    return SWEEPS


def add_parser(sub, one_of: str) -> None:
    b = sub.add_parser("bench", help="run a benchmark sweep; rows go to <out-dir>/<sweep>.jsonl", formatter_class=a.Help)
    b.add_argument("sweep", help="one of: " + ", ".join(sorted(sweeps())))
    b.add_argument("--quick", action="store_true", help="the CI-sized version")
    a.device(b, "device(s) to sweep (default: the default device)", repeat=True)
    b.add_argument("--out-dir", default="reports", help="where rows, reports and images go (default: ./reports)")
    b.add_argument("--scenes", help="folder of the scenes (default: $WSOFT_SCENES, else the stages installed with wsoft)")
    b.add_argument("--fresh", action="store_true", help="discard earlier rows instead of resuming")
    b.add_argument("--workers", type=int, metavar="N", help="run the rows on an embedded Dask cluster of N worker processes "
                   "(needs wsoft[dist]; the first worker alone times, the others compute references)")
    b.add_argument("--scheduler", metavar="ADDRESS", help="run the rows on a running Dask cluster (tcp://HOST:8786); its workers that "
                   "may time declare --resources MACHINE=1 (GPU=1 for CUDA)")
    b.add_argument("--resources", metavar="NAME=N[,...]", help="what every embedded worker declares (MACHINE=1: each times on its own; "
                   "default: the first worker holds MACHINE=1,GPU=1)")
    b.add_argument("--threads-per-worker", type=int, default=1, metavar="N", help="Dask threads of each embedded worker (default 1)")
    b.add_argument("--cache-dir", metavar="DIR", help="the references' cache, a folder every worker sees (default: $WSOFT_CACHE_DIR, "
                   "else ~/.cache/wsoft)")
    from wsoft.bench.regress import add_gate_arguments

    add_gate_arguments(b)
    b.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.bench.harness import run_sweep, sweep_name
    from wsoft.bench.html_report import write_html
    from wsoft.bench.regress import check_threshold, gate_kwargs

    name = sweep_name(args.sweep)
    for d in args.device or []:
        check_device(d)
    check_output(args.out_dir, "--out-dir", folder=True)
    check_threshold(args.time_threshold)
    from wsoft.bench.dist import parse_resources

    dist = dict(workers=args.workers, scheduler=args.scheduler, resources=parse_resources(args.resources),
                threads_per_worker=args.threads_per_worker, cache_dir=args.cache_dir)
    with CompileNotice((args.device or [None])[0]):
        return run_sweep(name, quick=args.quick, device=args.device, out_dir=args.out_dir, fresh=args.fresh, scenes=args.scenes, **dist,
                         **gate_kwargs(args), page=write_html)
