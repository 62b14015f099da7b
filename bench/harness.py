"""Harness core: sweeps of scenes x techniques x parameters x devices.

Each finished row is appended to ``reports/<sweep>.jsonl`` at once (a rerun skips rows
already there, so an interrupted sweep resumes); a progress bar shows the sweep; the sweep
ends by writing ``reports/<sweep>.md``. ``--quick`` is the CI-sized version and writes
``<sweep>-quick.*`` so it never mixes with the full results.

References are cached on disk (``$WSOFT_CACHE_DIR``, default ``~/.cache/wsoft``) by scene
file (path, size, modification time), time code, camera, light, resolution, sample count
and seed.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "usd_scenes"
SWEEPS = {"foundation": "bench.foundation", "filtered": "bench.filtered", "essm": "bench.essm", "essm-table1": "bench.essm_table1", "essm-table2": "bench.essm_table2",
          "ssm": "bench.ssm", "ssm-table1": "bench.ssm_table1", "ssm-table2": "bench.ssm_table2"}
REFERENCE_VERSION = 1  # bump when the reference's sampling changes


def scene_file(name: str) -> str:
    p = Path(name)
    if not p.suffix:
        for ext in (".usda", ".usdc", ".usdz", ".usd"):
            if (SCENES / (name + ext)).exists():
                return str(SCENES / (name + ext))
    return str(p if p.is_absolute() else SCENES / p)


def cache_dir() -> Path:
    d = Path(os.environ.get("WSOFT_CACHE_DIR", Path.home() / ".cache" / "wsoft")) / "references"
    d.mkdir(parents=True, exist_ok=True)
    return d


_SCENES: dict[str, object] = {}


def load(name: str):
    import wsoft

    f = scene_file(name)
    if f not in _SCENES:
        _SCENES[f] = wsoft.load_scene(f)
    return _SCENES[f]


def reference(name: str, *, width: int, height: int, light: str | None, samples: int, seed: int = 0, camera: str | None = None,
              device: str | None = None, casters: str = "all") -> dict:
    """The cached reference (V, V_stderr, A and the ms it took) for a view of a scene.

    ``casters = "dynamic"``: only the dynamic casters occlude (the ground truth of Salzman's mask)."""
    import wsoft

    f = scene_file(name)
    st = os.stat(f)
    ident = json.dumps([os.path.abspath(f), st.st_size, st.st_mtime_ns, camera, light, width, height, samples, seed, REFERENCE_VERSION]
                       + ([casters] if casters != "all" else []))
    path = cache_dir() / (hashlib.sha256(ident.encode()).hexdigest()[:24] + ".npz")
    if path.exists():
        z = np.load(path)
        return {k: z[k] for k in z.files} | {"cached": True}
    fr = wsoft.render(load(name), "reference", width=width, height=height, camera=camera, light=light, device=device, samples=samples, seed=seed, casters=casters)
    out = {"V": fr.V, "V_stderr": fr["V_stderr"], "A": fr["A"], "ms": np.float64(fr.stats["timings_ms"]["total"])}
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **out)
    os.replace(tmp, path)
    return out | {"cached": False}


def measure_render(name: str, technique: str, params: dict, *, device: str, width: int, height: int, light: str | None, repeats: int = 3):
    """Render once to warm up (kernel compiles), then ``repeats`` times; the median run's frame and stats."""
    import wsoft

    scene = load(name)
    kw = dict(width=width, height=height, light=light, device=device, **params)
    wsoft.render(scene, technique, **kw)
    runs = [wsoft.render(scene, technique, **kw) for _ in range(repeats)]
    totals = [r.stats["timings_ms"]["total"] for r in runs]
    med = runs[totals.index(statistics.median_low(totals))]
    med.stats["timings_ms_runs"] = totals
    return med


def read_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:  # a row cut short by an interruption
                    continue
    return rows


def drop_partial_row(path: Path) -> None:
    """Cut a last line left unfinished by an interruption, so new rows start on a fresh line."""
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def append_row(path: Path, row: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(row, default=_jsonable) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _jsonable(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def case_key(case: dict) -> str:
    return json.dumps(case, sort_keys=True)


def machine() -> dict:
    from wsoft.parallel import cpu_threads

    return {"python": platform.python_version(), "cpu": platform.processor() or platform.machine(), "threads": cpu_threads(), "cores": os.cpu_count()}


def run_sweep(name: str, *, quick: bool = False, device: list[str] | None = None, out_dir: str = "reports", fresh: bool = False) -> int:
    from tqdm import tqdm

    from wsoft.errors import ParameterError, WsoftError
    from wsoft.parallel import resolve_device

    if name not in SWEEPS:
        raise ParameterError(f"unknown sweep {name!r}; sweeps: {', '.join(sorted(SWEEPS))}")
    mod = importlib.import_module(SWEEPS[name])
    devices = [resolve_device(d) for d in (device or [None])]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"{name}-quick" if quick else name
    jsonl = out / f"{stem}.jsonl"
    if fresh and jsonl.exists():
        jsonl.unlink()
    drop_partial_row(jsonl)
    done = {r["key"] for r in read_rows(jsonl)}
    cases = mod.cases(quick=quick, devices=devices)
    todo = [c for c in cases if case_key(c) not in done]
    print(f"sweep {name}{' (quick)' if quick else ''}: {len(cases)} rows, {len(cases) - len(todo)} already in {jsonl}", file=sys.stderr)
    failed = 0
    ctx = {"out_dir": out, "stem": stem, "quick": quick}
    for case in tqdm(todo, desc=name, unit="row", file=sys.stderr):
        t0 = time.time()
        try:
            row = mod.run_case(case, ctx)
        except WsoftError as exc:
            failed += 1
            tqdm.write(f"row failed ({exc.line()}): {case_key(case)}", file=sys.stderr)
            continue
        row.update({"key": case_key(case), "sweep": name, "case": case, "finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "row_seconds": round(time.time() - t0, 2), "machine": machine()})
        append_row(jsonl, row)
    rows = [r for r in read_rows(jsonl) if r["key"] in {case_key(c) for c in cases}]
    cmd = f"wsoft bench {name}" + (" --quick" if quick else "") + "".join(f" --device {d}" for d in (device or []))
    md = out / f"{stem}.md"
    mod.report(rows, md, ctx | {"command": cmd})
    print(f"wrote {md} ({len(rows)} rows){f'; {failed} rows failed' if failed else ''}", file=sys.stderr)
    return 1 if failed else 0
