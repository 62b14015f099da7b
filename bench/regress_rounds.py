"""The regression gate's timed rounds: every render row of a sweep timed again, round after round
across the rows, so that each row's rounds sample the host's load over the whole sweep.

A sweep times each row three times in a row (:func:`wsoft.bench.harness.measure`): those rounds share
one moment of the host's load, and three against three can never reach the gate's corrected level
(:func:`wsoft.bench.regress_stats.min_p`). With ``wsoft bench SWEEP --save NAME`` or
``--baseline NAME``, :func:`time_rounds` renders every render row of this host once more per round
(after the sweep, its kernels compiled and its scenes loaded), in round i in the sweep's order and in
round i + 1 in reverse, as airspeed velocity interleaves its rounds: a load that rises through the
run falls on every row alike. Each row keeps its rounds' frame totals in ``frame_ms_rounds``
(wall clock: ``frame_ms``) and their CPU times in ``frame_cpu_ms_rounds`` (``frame_cpu_ms``: the
frame's passes' ``time.process_time``, every thread of the process); the sweep's own
``timings_ms_runs`` and report stay as they were.

Before each of a row's rounds, a fixed workload that no wsoft code takes part in (:func:`host_once`:
one Warp kernel of hashes and square roots, the same on every run) is timed too, in
``host_cpu_ms_rounds`` and ``host_ms_rounds``: how fast the host ran at that moment.

The gate judges one of three (``--timer``, :func:`judged_time`): **cpu** counts
what the frame's code spent on the CPU, which other processes on the host do not add to (they
still slow it through shared caches, memory bandwidth and clocks); **host** (the default) divides each round's
CPU time by the host workload's CPU time just before it (scaled to :data:`HOST_NOMINAL_MS`), so
that the host running slower or faster between two runs (its clocks, a neighbour on its caches)
cancels, while wsoft's own code running slower does not (the host workload is none of its code);
**wall** counts the time a user waits, parallel efficiency included, and is worth judging on a
runner that runs nothing else. In the proof runs of ``docs/ci.md``
(``python -m wsoft.bench.regress_proof``, 2 cores, 1-minute load 2.8-4.6) the baseline's 16 pcf
rounds spread from 18 to 28 ms on the wall clock, from 11 to 17 ms in CPU time and from 8.1 to
11.6 in host units.
"""

from __future__ import annotations

import json
import platform
from pathlib import Path

from wsoft.bench.regress_stats import DEFAULT_TIMER

# 16 against 16 reach p = 2 / C(32, 16) = 3.3e-9, far below any run's corrected level; fewer lose power: for rounds spread
# by 15 % of their mean, a 20 % slowdown reaches p ~ 0.01 over 8 rounds against 8 and ~ 0.0002 over 16 (normal approximation)
ROUNDS = 16
KEY = "frame_ms_rounds"  # each round's frame time on the wall clock (``timings_ms["total"]``)
CPU_KEY = "frame_cpu_ms_rounds"  # each round's CPU time: the frame's passes' ``cpu_ms`` summed (``time.process_time``, every thread)
HOST_KEY = "host_cpu_ms_rounds"  # the host workload's CPU time before each round (host_once)
HOST_WALL_KEY = "host_ms_rounds"  # and its wall-clock time
HOST_NOMINAL_MS = 10.0  # the host timer's unit: a round's CPU time on a host whose workload takes this long
HOST_STEPS, HOST_THREADS = 256, 4096  # the host workload: about 14 ms of one core of the machine of docs/ci.md
TIMERS = ("cpu", "host", "wall")


def timeable(row: dict) -> bool:
    """A row of one technique rendered on one stage (``kind`` render, with its stage, technique,
    size and device), timed on this host."""
    case = row.get("case") or {}
    here = (row.get("machine") or {}).get("host", platform.node()) == platform.node()
    whole = all(case.get(k) is not None for k in ("scene", "technique", "width", "height", "device"))
    return case.get("kind") == "render" and whole and "timings_ms_runs" in row and here


def time_once(case: dict) -> tuple[float, float]:
    """One frame of a render row's case, as the sweep times it: (its frame's ``timings_ms["total"]``,
    the CPU time of its passes, ``cpu_ms`` summed), in milliseconds."""
    import warnings

    import wsoft
    from wsoft.bench.harness import first_light, load

    params = dict(case.get("params") or {})
    spp = int(params.pop("pixel_samples", 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sweep's own render of this case reported them in its row
        fs = wsoft.render(load(case["scene"]), [(case["technique"], params)], width=case["width"], height=case["height"],
                          light=first_light(case["scene"], case.get("light")), device=case["device"], pixel_samples=spp)
    st = next(iter(fs.values())).stats
    return float(st["timings_ms"]["total"]), float(sum(st["cpu_ms"].values()))


def host_once() -> tuple[float, float]:
    """The host workload once (:mod:`wsoft.bench.regress_host`): (wall-clock ms, CPU ms of this process)."""
    from wsoft.bench.regress_host import host_once as once

    return once(HOST_STEPS, HOST_THREADS)


def host_scaled(cpu: list, host: list) -> list[float]:
    """Each round's CPU time in the host timer's unit: ``cpu[i] * HOST_NOMINAL_MS / host[i]``."""
    return [c * HOST_NOMINAL_MS / h for c, h in zip(cpu, host) if h and h > 0]


def time_rounds(jsonl: Path, keys: set[str], rounds: int = ROUNDS) -> int:
    """Time the timeable rows of ``jsonl`` whose key is in ``keys`` ``rounds`` times after a warm-up
    frame each, alternating the rows' order from round to round, and write each row's wall-clock
    totals to its ``frame_ms_rounds`` and their CPU times to ``frame_cpu_ms_rounds``
    (the file rewritten whole, then moved into place). Returns the number of rows timed."""
    import sys

    from wsoft.bench.harness import append_row, read_rows

    if rounds <= 0:
        return 0
    rows = read_rows(Path(jsonl))
    todo = [r for r in rows if r.get("key") in keys and not r.get("failed") and timeable(r)]
    if not todo:
        return 0
    for r in todo:
        r[KEY], r[CPU_KEY], r[HOST_KEY], r[HOST_WALL_KEY] = [], [], [], []
    print(f"gate: timing {len(todo)} rows x {rounds} rounds, alternating order", file=sys.stderr)
    host_once()  # its kernel compiled or loaded
    for r in todo:  # a warm-up frame each, not kept (a scene loaded or a kernel compiled since the row ran)
        time_once(r["case"])
    for i in range(rounds):
        for r in todo if i % 2 == 0 else reversed(todo):
            host_wall, host_cpu = host_once()
            wall, cpu = time_once(r["case"])
            r[KEY].append(wall)
            r[CPU_KEY].append(cpu)
            r[HOST_WALL_KEY].append(host_wall)
            r[HOST_KEY].append(host_cpu)
    tmp = Path(jsonl).with_suffix(".rounds.tmp")
    tmp.unlink(missing_ok=True)
    for r in rows:
        append_row(tmp, r)
    tmp.replace(jsonl)
    return len(todo)


def scaled(row: dict, factor: float) -> dict:
    """``row`` (a copy) with every round time the gate reads multiplied by ``factor``."""
    out = json.loads(json.dumps(row))
    for k in ("timings_ms_runs", KEY, CPU_KEY):
        if k in out:
            out[k] = [t * factor for t in out[k]]
    return out


def judged_time(name: str, names, timer: str = DEFAULT_TIMER) -> bool:
    """Whether the gate judges the time metric ``name`` of a row whose metrics are ``names``: with
    ``timer`` cpu, a wall-clock ``frame_ms`` whose row also has ``frame_cpu_ms`` is left out (the
    CPU rounds stand for it); with host, ``frame_cpu_host_ms`` stands for both where the row has it;
    with wall, the CPU metrics are left out. A time metric without its counterpart (another sweep's
    rounds) is judged by every timer."""
    if timer not in TIMERS:
        from wsoft.errors import ParameterError

        raise ParameterError(f"--timer {timer}: give one of {', '.join(TIMERS)}")
    if timer == "wall":
        return "frame_cpu_ms" not in name and "frame_cpu_host_ms" not in name
    if timer == "cpu":
        return "frame_cpu_host_ms" not in name and not ("frame_ms" in name and name.replace("frame_ms", "frame_cpu_ms") in names)
    if "frame_cpu_host_ms" in name:
        return True
    if "frame_cpu_ms" in name:
        return name.replace("frame_cpu_ms", "frame_cpu_host_ms") not in names
    return not ("frame_ms" in name and (name.replace("frame_ms", "frame_cpu_ms") in names or name.replace("frame_ms", "frame_cpu_host_ms") in names))
