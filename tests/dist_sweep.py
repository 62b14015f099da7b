"""A sweep small enough for the distributed tests (tests/test_dist.py): three rows of ``hard`` on two
bundled stages at 48x36, plus the rows a test asks for in ``$WSOFT_DIST_SWEEP`` (a JSON list):
``{"kind": "slow", "dir": D, "seconds": S}`` writes ``D/started-<pid>-<ns>`` and sleeps S seconds before
its row (a job to kill its worker under), ``{"kind": "raise"}`` raises a WsoftError,
``{"kind": "crash"}`` kills its own worker process. Workers import it by name (``dist_sweep``),
with tests/ on their path."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

from wsoft.bench.common import render_references, render_row

SWEEP = "dist-test"
MODULE = "dist_sweep"  # the name workers import it by
references = render_references


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = [{"kind": "render", "scene": scene, "light": None, "device": devices[0], "width": 48, "height": 36, "ref_samples": 16,
            "technique": "hard", "params": {"shadow_map_size": size}}
           for scene, size in (("box_plane", 256), ("box_plane", 512), ("contact", 256))]
    return out + json.loads(os.environ.get("WSOFT_DIST_SWEEP", "[]"))


def run_case(case: dict, ctx: dict) -> dict:
    if case["kind"] == "slow":
        (Path(case["dir"]) / f"started-{os.getpid()}-{time.time_ns()}").write_text("")
        time.sleep(case["seconds"])
        return {"slow": True}
    if case["kind"] == "raise":
        from wsoft.errors import ParameterError

        raise ParameterError("this row raises on purpose")
    if case["kind"] == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    return render_row(case, ctx)


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    md.write_text("\n".join(report_header(SWEEP, rows, md, ctx)) + "\n")


def register() -> None:
    """Make ``wsoft bench dist-test`` this sweep, in this process."""
    from wsoft.bench import harness

    harness.SWEEPS[SWEEP] = MODULE


if __name__ == "__main__":  # the driver as its own process: python dist_sweep.py ARGS (wsoft's command line)
    import sys

    from wsoft.cli import main

    register()
    sys.exit(main(sys.argv[1:]))
