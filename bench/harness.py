"""Harness core: sweeps of scenes x techniques x parameters x devices.

Each finished row is appended to ``<out-dir>/<sweep>.jsonl`` at once (a rerun skips rows
already there, so an interrupted sweep resumes); a progress bar shows the sweep; the sweep
ends by writing ``<out-dir>/<sweep>.md``. ``--quick`` is the CI-sized version and writes
``<sweep>-quick.*`` so it never mixes with the full results (``.gitignore`` covers those).
``--out-dir`` defaults to ``./reports``.

Scenes are looked up by name in the bundled stages (``wsoft.usd_scenes``, installed with the
package) or in ``--scenes DIR`` / ``$WSOFT_SCENES``.

References are cached on disk (``$WSOFT_CACHE_DIR`` or ``--cache-dir``, default ``~/.cache/wsoft``)
by scene file (path, size, modification time), time code, camera, light, resolution, sample count
and seed.

``--workers N`` / ``--scheduler ADDRESS`` run the rows as jobs on Dask workers
(:mod:`wsoft.bench.dist`); this process still writes every row, as it finishes.
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

from wsoft.bench.regress_stats import DEFAULT_TIMER

SWEEPS = {"foundation": "wsoft.bench.foundation", "filtered": "wsoft.bench.filtered", "essm": "wsoft.bench.essm",
          "essm-table1": "wsoft.bench.essm_table1", "essm-table2": "wsoft.bench.essm_table2", "ssm": "wsoft.bench.ssm", "izb": "wsoft.bench.izb",
          "ssm-table1": "wsoft.bench.ssm_table1", "ssm-table2": "wsoft.bench.ssm_table2", "pareto": "wsoft.bench.pareto",
          "adversarial": "wsoft.bench.adversarial", "usd-pipeline": "wsoft.bench.usd_pipeline",
          "instancing": "wsoft.bench.instancing", "stsv": "wsoft.bench.stsv", "modern": "wsoft.bench.modern",
          "temporal": "wsoft.bench.temporal", "cube": "wsoft.bench.cube", "distributed": "wsoft.bench.distributed",
          "auto": "wsoft.bench.auto", "skinning": "wsoft.bench.skinning",
          "scaling": "wsoft.bench.scaling", "worlds": "wsoft.bench.worlds",
          "lights": "wsoft.bench.lights"}
SWEEP_ALIASES = {"usd_pipeline": "usd-pipeline"}  # other spellings `wsoft bench` accepts (words joined by "-" in SWEEPS)
REFERENCE_VERSION = 7  # a key of the reference cache: bump it when the reference's V, V_stderr or shaded R, G, B change
_SCENE_DIR: Path | None = None


def scenes_dir() -> Path:
    """Where scenes are looked up: ``--scenes`` / ``$WSOFT_SCENES``, else the bundled stages."""
    if _SCENE_DIR is not None:
        return _SCENE_DIR
    from wsoft.env import scenes_dir as env_scenes

    env = env_scenes()
    if env is not None:
        return env
    from wsoft import usd_scenes

    return usd_scenes.folder()


def set_scenes_dir(path: str | None) -> None:
    global _SCENE_DIR
    _SCENE_DIR = Path(path) if path else None


def scene_file(name: str) -> str:
    """The file of scene ``name`` (a bundled name such as ``box_plane``, or a path)."""
    from wsoft.errors import ParameterError

    p = Path(name)
    if p.suffix and p.is_file():
        return str(p)
    d = scenes_dir()
    if not d.is_dir():
        raise ParameterError(f"scene folder {d} does not exist (give the bundled stages' folder with --scenes DIR)")
    for cand in [d / name] + [d / (name + ext) for ext in (".usda", ".usdc", ".usdz", ".usd")]:
        if cand.is_file():
            return str(cand)
    raise ParameterError(f"scene {name!r} not found in {d} (give its folder with --scenes DIR)")


def cache_dir() -> Path:
    from wsoft.env import cache_dir as env_cache

    d = env_cache() / "references"
    d.mkdir(parents=True, exist_ok=True)
    return d


_SCENES: dict[str, object] = {}


def load(name: str):
    """A stage by name (:func:`scene_file`), loaded once, as the CLI loads it
    (:func:`~wsoft.pipeline.load_stage`, ``instancing=auto``): one triangle soup, unless its instances
    place more triangles than would fit flattened (``forest``: 56 million), which stay instances."""
    from wsoft.pipeline import load_stage

    f = scene_file(name)
    if f not in _SCENES:
        _SCENES[f] = load_stage(f)
    return _SCENES[f]


def first_light(name: str, light: str | None) -> str:
    """The light a row renders: ``light``, else the scene's first shadow-casting light (its path)."""
    return light or load(name).lights[0].path


def reference_path(name: str, *, width: int, height: int, light: str | None, samples: int, seed: int = 0, camera: str | None = None,
                   casters: str = "all", time: float | None = None, device: str | None = None) -> Path:
    """The file in :func:`cache_dir` that holds :func:`reference`'s result for these arguments: named by
    a hash of the scene file (path, size, modification time), the view, the light and the sampling
    (``device`` does not enter: the reference is the same on every device)."""
    f = scene_file(name)
    st = os.stat(f)
    light = first_light(name, light)
    ident = json.dumps([os.path.abspath(f), st.st_size, st.st_mtime_ns, camera, light, width, height, samples, seed, REFERENCE_VERSION]
                       + ([casters] if casters != "all" else []) + ([float(time)] if time is not None else []))
    return cache_dir() / (hashlib.sha256(ident.encode()).hexdigest()[:24] + ".npz")


def reference(name: str, *, width: int, height: int, light: str | None, samples: int, seed: int = 0, camera: str | None = None,
              device: str | None = None, casters: str = "all", time: float | None = None, scene=None) -> dict:
    """The cached reference (V, V_stderr, A, its shaded image R, G, B lit by that light alone, and
    the ms it took) for a view of one light of a scene (``light``: a path or name; None: the first
    shadow-casting light).

    ``casters = "dynamic"``: only the dynamic casters occlude (the ground truth of Salzman's mask).
    ``time``: the stage at that time code (a sequence's frame; ``scene``: the stage already loaded
    there), a key of the cache; None: as :func:`load` reads it."""
    import wsoft

    f = scene_file(name)
    light = first_light(name, light)
    path = reference_path(name, width=width, height=height, light=light, samples=samples, seed=seed, camera=camera, casters=casters, time=time)
    if path.exists():
        z = np.load(path)
        return {k: z[k] for k in z.files} | {"cached": True, "samples": samples}
    if scene is None:
        from wsoft.pipeline import load_stage

        scene = load(name) if time is None else load_stage(f, time=time)
    fr = wsoft.render(scene, "reference", width=width, height=height, camera=camera, light=light, device=device, samples=samples, seed=seed, casters=casters)
    out = {"V": fr.V, "V_stderr": fr["V_stderr"], "A": fr["A"], "R": fr["R"], "G": fr["G"], "B": fr["B"],
           "ms": np.float64(fr.stats["timings_ms"]["total"])}
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **out)
    os.replace(tmp, path)
    return out | {"cached": False, "samples": samples}


def ground_truth(name: str, ref: dict, light: str | None):
    """A cached reference as the metric pass's :class:`~wsoft.metrics.GroundTruth` for ``light``,
    with its shaded image (the rows render that light alone, so the error passes add ꟻLIP)."""
    from wsoft.metrics import GroundTruth

    scene = load(name)
    path = first_light(name, light)
    label = scene.light_label(scene.find_light(path))
    return GroundTruth({label: {"V": ref["V"], "V_stderr": ref["V_stderr"], "A": ref["A"]}}, int(ref["samples"]),
                       shaded={c: ref[c] for c in "RGB"})


def measure(name: str, techniques: list, *, device: str, width: int, height: int, light: str | None, truth=None, repeats: int = 3,
            pixel_samples: int = 1, once_over_ms: float | None = None):
    """Render ``techniques`` (a list as :func:`wsoft.render` takes) in one graph, with their error
    against ``truth`` (a GroundTruth) when given: once to warm up (kernel compiles), measuring the
    errors (:func:`wsoft.compare`: the metric passes, ꟻLIP included, run once), then ``repeats``
    times without them. Returns the FrameSet whose frames carry each technique's median run (its
    ``timings_ms_runs`` lists every run's total) and the warm-up's errors (the techniques are
    deterministic: every run gives the same V). ``once_over_ms``: a technique whose warm-up frame
    took longer is not rendered again; its frame is the warm-up's, ``timings_ms_runs`` that one
    total and ``stats["timed_once"]`` true (a setting minutes a frame would hold a sweep for hours)."""
    import wsoft

    scene = load(name)
    kw = dict(width=width, height=height, light=first_light(name, light), device=device, pixel_samples=pixel_samples)
    first = wsoft.render(scene, list(techniques), **kw) if truth is None else wsoft.compare(scene, list(techniques), ground_truth=truth, **kw)
    labels = list(first)[: len(techniques)]  # the techniques' frames, in their order
    slow = {lb for lb in labels if once_over_ms is not None and first[lb].stats["timings_ms"]["total"] > once_over_ms}
    again = [t for t, lb in zip(techniques, labels) if lb not in slow]
    runs = [wsoft.render(scene, again, **kw) for _ in range(repeats)] if again else []  # labels: name and parameters, not place
    out = runs[0] if runs else first
    for label in slow:
        fr = first[label]
        fr.stats["timings_ms_runs"] = [fr.stats["timings_ms"]["total"]]
        fr.stats["timed_once"] = True
        out.frames[label] = fr
    for label in [lb for lb in labels if lb not in slow]:
        totals = [r[label].stats["timings_ms"]["total"] for r in runs]
        med = runs[totals.index(statistics.median_low(totals))][label]
        med.stats["timings_ms_runs"] = totals
        for k in ("error", "errors", "error_against"):
            if k in first[label].stats:
                med.stats[k] = first[label].stats[k]
        med.error_maps = first[label].error_maps
        out.frames[label] = med
    out.frames = {lb: out.frames[lb] for lb in labels}  # the order of ``techniques``
    return out


def measure_render(name: str, technique: str, params: dict, *, device: str, width: int, height: int, light: str | None, repeats: int = 3,
                   truth=None):
    """One technique as :func:`measure` (``params`` may hold ``pixel_samples``): its median frame."""
    params = dict(params)
    spp = int(params.pop("pixel_samples", 1))
    fs = measure(name, [(technique, params)], device=device, width=width, height=height, light=light, truth=truth, repeats=repeats,
                 pixel_samples=spp)
    return next(iter(fs.values()))


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
    """Where a row was measured: the host, its CPU, the threads Warp's CPU launches use, the cores,
    and the host's load (1-minute load average, ``os.getloadavg``) as the row finished."""
    from wsoft.parallel import cpu_threads

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"python": platform.python_version(), "cpu": platform.processor() or platform.machine(), "threads": cpu_threads(), "cores": os.cpu_count(),
            "host": platform.node(), "load": None if load is None else round(load, 2)}


def sweep_name(name: str) -> str:
    """The sweep ``name`` stands for: a key of :data:`SWEEPS`, or one of :data:`SWEEP_ALIASES`;
    anything else is a one-line error suggesting the closest names."""
    from wsoft.errors import ParameterError, suggestion

    name = SWEEP_ALIASES.get(name, name)
    if name not in SWEEPS:
        raise ParameterError(f"unknown sweep {name!r}{suggestion(name, SWEEPS)}; sweeps: {', '.join(sorted(SWEEPS))}")
    return name


def finished_rows(path: Path) -> list[dict]:
    """The rows of ``path`` that hold a result: rows recorded as failed (``"failed"``: a job of a
    distributed sweep that raised or killed its workers) are left out, so a rerun runs them again."""
    return [r for r in read_rows(path) if not r.get("failed")]


def run_in_process(name: str, mod, todo: list[dict], ctx: dict, jsonl: Path) -> int:
    """Run the cases ``todo`` of sweep ``name`` (module ``mod``) one after another in this process,
    appending each row to ``jsonl`` as it finishes; returns the number of rows that failed."""
    from tqdm import tqdm

    from wsoft.errors import WsoftError

    failed = 0
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
    return failed


def run_sweep(name: str, *, quick: bool = False, device: list[str] | None = None, out_dir: str = "reports", fresh: bool = False,
              scenes: str | None = None, workers: int | None = None, scheduler: str | None = None, resources: dict | None = None,
              threads_per_worker: int = 1, cache_dir: str | None = None, save: str | None = None, baseline: str | None = None,
              time_threshold: float = 0.10, rounds: int = 16, timer: str = DEFAULT_TIMER, page=None) -> int:
    """Run sweep ``name`` (see the module docstring). ``workers`` (an embedded Dask cluster of that many
    processes, ``threads_per_worker`` threads each) or ``scheduler`` (a running Dask scheduler's
    address) send its rows to Dask workers (:mod:`wsoft.bench.dist`); ``resources``: what each
    embedded worker declares. ``cache_dir``: the references' cache (``$WSOFT_CACHE_DIR``), a folder
    every worker sees. The regression gate (:mod:`wsoft.bench.regress`): ``save`` keeps the rows as
    baseline ``save`` (``<out_dir>/baselines/NAME/``); ``baseline`` (a saved name, a baseline folder or
    a rows file) compares them with it, writes ``<out_dir>/<sweep>-regress.md`` and returns 1 on a
    regression (a slowdown beyond ``1 + time_threshold`` that the rounds' spread confirms, an error
    grown beyond its floor and standard errors, a vanished row, a NaN); ``rounds``: the gate's timed
    rounds per render row and ``timer`` the time judged, host, cpu or wall (:mod:`wsoft.bench.regress_rounds`). ``page``: called as
    ``page(stem, rows, out_dir, baseline_rows)`` after the report, returning the path it wrote (the
    command line passes :func:`wsoft.bench.html_report.write_html`: ``<out_dir>/<stem>.html``)."""
    from wsoft.bench import regress
    from wsoft.errors import ParameterError
    from wsoft.parallel import resolve_device

    name = sweep_name(name)
    gate = regress.before_sweep(save, baseline, out_dir, time_threshold, rounds)
    mod = importlib.import_module(SWEEPS[name])
    if scenes and not Path(scenes).is_dir():  # a bad --scenes is an error before anything runs (or is remembered)
        raise ParameterError(f"--scenes {scenes}: no such folder")
    distributed = workers is not None or bool(scheduler)
    if distributed:
        from wsoft.bench import dist

        dist.check(workers=workers, scheduler=scheduler, resources=resources, threads_per_worker=threads_per_worker)
    if cache_dir:
        os.environ["WSOFT_CACHE_DIR"] = str(Path(cache_dir).resolve())
    set_scenes_dir(scenes)
    devices = [resolve_device(d) for d in (device or [None])]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = getattr(mod, "REPORT", name)  # a sweep module may name its report's files otherwise
    stem = f"{report}-quick" if quick else report
    jsonl = out / f"{stem}.jsonl"
    if fresh and jsonl.exists():
        jsonl.unlink()
    drop_partial_row(jsonl)
    done = {r["key"] for r in finished_rows(jsonl)}
    cases = mod.cases(quick=quick, devices=devices)
    todo = [c for c in cases if case_key(c) not in done]
    print(f"sweep {name}{' (quick)' if quick else ''}: {len(cases)} rows, {len(cases) - len(todo)} already in {jsonl}", file=sys.stderr)
    ctx = {"out_dir": out, "stem": stem, "quick": quick}
    if distributed:
        failed = dist.run_jobs(name, SWEEPS[name], todo, ctx, jsonl, workers=workers, scheduler=scheduler, resources=resources,
                               threads_per_worker=threads_per_worker, scenes=scenes,
                               cache_dir=os.environ["WSOFT_CACHE_DIR"] if cache_dir else None)
    else:
        failed = run_in_process(name, mod, todo, ctx, jsonl)
    keys = {case_key(c) for c in cases}
    rows = [r for r in finished_rows(jsonl) if r["key"] in keys]
    cmd = f"wsoft bench {name}" + (" --quick" if quick else "") + "".join(f" --device {d}" for d in (device or [])) + \
        (f" --out-dir {out_dir}" if str(out_dir) != "reports" else "") + (f" --scenes {scenes}" if scenes else "") + \
        (f" --workers {workers}" if workers is not None else "") + (f" --scheduler {scheduler}" if scheduler else "")
    md = out / f"{stem}.md"
    mod.report(rows, md, ctx | {"command": cmd})
    written = [md]
    if page is not None:
        base_rows = None
        if gate is not None and stem in gate.files:
            base_rows = [r for r in finished_rows(gate.files[stem]) if r.get("key") in keys]
        written.append(page(stem, rows, out, base_rows))
    print(f"wrote {' and '.join(map(str, written))} ({len(rows)} rows){f'; {failed} rows failed' if failed else ''}", file=sys.stderr)
    regressed = regress.after_sweep(stem, jsonl, keys, out, save, gate, time_threshold, rounds, timer) if (save or gate) else 0
    return 1 if failed or regressed else 0
