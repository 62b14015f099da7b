"""The regression gate's inputs: a sweep's rows flattened to named metrics, the sources rows come
from (a saved baseline's name, a baseline folder, a ``.jsonl`` rows file) and the fingerprint of
the machine that measured them.

A row flattens to ``<label>.<metric>`` names whatever its sweep: a row of one technique (``label``
or ``technique``) gives ``pcf.frame_ms`` (its ``timings_ms_runs``), ``pcf.mae_penumbra``,
``pcf.flip``, ``pcf.nan_pixels`` (the time from the gate's timed rounds ``frame_ms_rounds`` where the
row has them, with ``pcf.frame_cpu_ms`` from ``frame_cpu_ms_rounds``, :mod:`wsoft.bench.regress_rounds`); a row holding several techniques in ``entries`` (``pareto``,
``temporal``, ``cube``, ``modern``) gives one set per entry label (``dcs(grid_size=1024).frame_ms``
from ``frame_ms_runs``, or from ``frame_ms_frames`` the sequence's per-frame times; ``esm.flicker``
with its ``flicker_se``); other ``*_ms_runs`` lists are time metrics of their own name.
"""

from __future__ import annotations

import json
import math
import platform
from dataclasses import dataclass, field
from pathlib import Path

from wsoft.bench.regress_rounds import CPU_KEY, HOST_KEY, host_scaled
from wsoft.bench.regress_stats import FLOORS, spread_se

BASELINES = "baselines"  # <out-dir>/baselines/NAME/ holds a saved baseline
FINGERPRINT = "fingerprint.json"
ACCURACY = tuple(FLOORS)  # error metrics judged against their floor and standard errors
COUNTS = ("nan_pixels", "flip_nan_pixels")  # counts that must not grow
TIME_NAMES = {"timings_ms_runs": "frame_ms", "frame_ms_runs": "frame_ms", "frame_ms_frames": "frame_ms", "frame_ms_rounds": "frame_ms",
              "frame_cpu_ms_rounds": "frame_cpu_ms"}
ROUNDS_OVER = {"frame_ms_rounds": "timings_ms_runs"}  # the gate's timed rounds, when a row has them, stand for the sweep's own
TRANSPARENT = ("error", "temporal")  # containers whose metrics are the entry's own (no name part)
SKIP = frozenset({"machine", "worker", "case", "key", "counters", "counters_last", "memory_bytes", "cpu_ms", "timings_ms", "timings_by_kind_ms",
                  "by_kind_ms", "pass_kinds", "pass_stages", "passes", "warnings", "params", "facing", "not_facing", "worst_frame", "cost",
                  "host_cpu_ms_rounds", "host_ms_rounds"})  # the host workload's rounds: a time of the host, not of a row (frame_cpu_host_ms)


@dataclass
class Metric:
    """One named measurement of a row: ``kind`` "time" (``samples``: the per-round times),
    "accuracy" (``value`` and its standard error ``se``) or "count"."""

    kind: str
    value: float | None = None
    samples: list = field(default_factory=list)
    se: float = 0.0


def _number(x) -> float | None:
    if isinstance(x, bool) or x is None:
        return None
    if isinstance(x, (int, float)):
        return float(x)
    if isinstance(x, str) and x.lower() in ("nan", "inf", "-inf", "infinity", "-infinity"):
        return float(x)
    return None


def _time_name(key: str) -> str | None:
    if key in TIME_NAMES:
        return TIME_NAMES[key]
    return key[: -len("_runs")] if key.endswith("_ms_runs") else None


def _entry_label(e: dict) -> str | None:
    return e.get("label") or e.get("technique") if isinstance(e, dict) else None


def flatten(row: dict) -> dict[str, Metric]:
    """The metrics of ``row`` by name (see the module docstring)."""
    out: dict[str, Metric] = {}

    def put(name: str, m: Metric) -> None:
        k, i = name, 2
        while k in out:
            k, i = f"{name}#{i}", i + 1
        out[k] = m

    def walk(obj: dict, prefix: str, context: dict) -> None:
        context = {**context, **obj}
        hidden = {ROUNDS_OVER[k] for k in obj if k in ROUNDS_OVER}
        for k, v in obj.items():
            if k in SKIP or k in hidden:
                continue
            tname = _time_name(k)
            if tname and isinstance(v, list):
                put(prefix + tname, Metric("time", samples=[x for x in (_number(s) for s in v) if x is not None]))
            elif k in ACCURACY and (v is None or _number(v) is not None):
                se = _number(context.get(f"{k}_se"))
                if se is None:
                    se = spread_se(context.get(f"{k}_frames"))
                put(prefix + k, Metric("accuracy", value=_number(v), se=se if se is not None and math.isfinite(se) else 0.0))
            elif k in COUNTS and (v is None or _number(v) is not None):
                put(prefix + k, Metric("count", value=_number(v)))
            elif isinstance(v, list) and v and all(_entry_label(e) for e in v):
                seen: dict[str, int] = {}
                for e in v:
                    label = _entry_label(e)
                    seen[label] = seen.get(label, 0) + 1
                    walk(e, f"{prefix}{label}{'' if seen[label] == 1 else '#' + str(seen[label])}.", {})
            elif isinstance(v, dict):
                walk(v, prefix if k in TRANSPARENT else f"{prefix}{k}.", context if k in TRANSPARENT else {})
        if isinstance(obj.get(CPU_KEY), list) and isinstance(obj.get(HOST_KEY), list):
            cpu, host = ([_number(x) for x in obj[k]] for k in (CPU_KEY, HOST_KEY))
            pairs = [(c, h) for c, h in zip(cpu, host) if c is not None and h is not None]
            put(prefix + "frame_cpu_host_ms", Metric("time", samples=host_scaled([c for c, _ in pairs], [h for _, h in pairs])))

    label = row.get("label") or row.get("technique")
    walk(row, f"{label}." if label else "", {})
    return out


def describe(row: dict) -> str:
    """A row in a few words: its scene, light, technique with parameters, resolution."""
    case = row.get("case") or {}
    parts = [str(case.get("scene") or case.get("name") or row.get("scene") or row.get("name") or "?")]
    light = case.get("light") or row.get("light")
    if light:
        parts.append(str(light).split("/")[-1])
    tech = case.get("technique")
    if tech:
        params = case.get("params") or {}
        parts.append(tech + (f"({', '.join(f'{k}={v}' for k, v in params.items())})" if params else ""))
    if case.get("width"):
        parts.append(f"{case['width']}x{case.get('height')}")
    if case.get("frames"):
        parts.append(f"frames {case['frames']}")
    return " ".join(parts)


# -- sources ----------------------------------------------------------------------------------------


@dataclass
class Source:
    """Rows to compare: ``files`` maps a rows file's stem (``filtered-quick``) to its path;
    ``fingerprint``: the machine that measured them, from the baseline's fingerprint.json (None
    for a bare rows file)."""

    given: str
    files: dict[str, Path]
    fingerprint: dict | None = None


def resolve(arg: str, out_dir: str | Path = "reports", flag: str = "") -> Source:
    """``arg`` as a source: a ``.jsonl`` rows file, a folder of them (a saved baseline), or the name
    of a baseline saved under ``<out_dir>/baselines/``; anything else is a one-line error naming it."""
    from wsoft.errors import ParameterError

    where = f"{flag} {arg}" if flag else arg
    p = Path(arg)
    if arg.endswith(".jsonl"):
        if not p.is_file():
            raise ParameterError(f"{where}: no such rows file")
        return Source(arg, {p.stem: p})
    if not p.is_dir():
        named = Path(out_dir) / BASELINES / arg
        if "/" in arg or not named.is_dir():
            saved = sorted(d.name for d in (Path(out_dir) / BASELINES).glob("*") if d.is_dir())
            raise ParameterError(f"{where}: neither a rows file (.jsonl), a baseline folder nor a baseline saved in {Path(out_dir) / BASELINES}"
                                 + (f" (saved: {', '.join(saved)})" if saved else ""))
        p = named
    files = {f.stem: f for f in sorted(p.glob("*.jsonl"))}
    if not files:
        raise ParameterError(f"{where}: folder {p} holds no rows file (.jsonl)")
    fp = None
    if (p / FINGERPRINT).is_file():
        try:
            fp = json.loads((p / FINGERPRINT).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise ParameterError(f"{where}: {p / FINGERPRINT} is not JSON") from None
    return Source(arg, files, fp)


def rows_of(path: Path) -> dict[str, dict]:
    """The finished rows of a rows file by their ``key`` (rows recorded as failed left out)."""
    from wsoft.bench.harness import finished_rows

    return {r["key"]: r for r in finished_rows(Path(path)) if "key" in r}


def pairs(old: Source, new: Source) -> list[tuple[str, Path, Path]]:
    """The rows files to compare: (stem, old file, new file) for every stem both sources hold; a
    source of one file pairs with the other's only file or the file of its stem."""
    from wsoft.errors import ParameterError

    common = sorted(set(old.files) & set(new.files))
    if common:
        return [(s, old.files[s], new.files[s]) for s in common]
    if len(old.files) == 1 and len(new.files) == 1:
        (so, fo), (_, fn) = next(iter(old.files.items())), next(iter(new.files.items()))
        return [(so, fo, fn)]
    raise ParameterError(f"{old.given} ({', '.join(old.files)}) and {new.given} ({', '.join(new.files)}) hold no rows file of the same sweep")


# -- fingerprints -----------------------------------------------------------------------------------


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :mod:`platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("model name", "hardware", "cpu model")) and ":" in line:
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def fingerprint() -> dict:
    """This machine and software: CPU model, Warp's CPU threads, Warp and wsoft versions, Python, host."""
    from importlib.metadata import PackageNotFoundError, version

    import warp

    from wsoft.parallel import cpu_threads

    try:
        ws = version("wsoft")
    except PackageNotFoundError:
        ws = "?"
    return {"cpu_model": cpu_model(), "threads": cpu_threads(), "warp": warp.config.version, "wsoft": ws, "python": platform.python_version(),
            "host": platform.node()}


def machine_of(row: dict, fp: dict | None) -> dict:
    """What identifies the machine a row was timed on: host, Warp's CPU threads (from the row's
    ``machine``, else the fingerprint) and the CPU model (the fingerprint's; None when unknown)."""
    m = row.get("machine") or {}
    fp = fp or {}
    return {"host": m.get("host", fp.get("host")), "threads": m.get("threads", fp.get("threads")), "cpu_model": fp.get("cpu_model")}


def other_machine(a: dict, b: dict) -> str | None:
    """Why two :func:`machine_of` differ (``"host vm vs ci-7"``), or None when they may be the same
    machine (a field unknown on one side does not count)."""
    diffs = [f"{k} {a[k]} vs {b[k]}" for k in ("host", "threads", "cpu_model") if a.get(k) is not None and b.get(k) is not None and a[k] != b[k]]
    return ", ".join(diffs) or None


def check_name(name: str) -> None:
    """A baseline's name is one word: a folder under ``<out-dir>/baselines/``."""
    from wsoft.errors import ParameterError

    if not name or "/" in name or "\\" in name or name in (".", ".."):
        raise ParameterError(f"--save {name!r}: a baseline's name is one word (no '/')")


def save(name: str, stem: str, rows: list[dict], out_dir: str | Path) -> Path:
    """Keep ``rows`` as baseline ``name``: ``<out_dir>/baselines/NAME/<stem>.jsonl`` with this
    machine's ``fingerprint.json``; returns the folder."""
    from wsoft.bench.harness import append_row

    check_name(name)
    d = Path(out_dir) / BASELINES / name
    d.mkdir(parents=True, exist_ok=True)
    f = d / f"{stem}.jsonl"
    tmp = f.with_suffix(".tmp")
    tmp.unlink(missing_ok=True)
    for r in rows:
        append_row(tmp, r)
    tmp.touch()
    tmp.replace(f)
    (d / FINGERPRINT).write_text(json.dumps(fingerprint(), indent=1) + "\n")
    return d
