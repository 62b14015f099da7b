"""A sweep's rows on Dask distributed: ``wsoft bench SWEEP --workers N`` or ``--scheduler ADDRESS``.

Every row of a sweep is one independent job, named by a content hash of its case (scene, light,
techniques, settings, frame) and the sweep (:func:`job_key`). The driver (the ``wsoft bench``
process) submits the jobs and alone writes the rows, each as its job finishes, so a killed driver
resumes from ``<sweep>.jsonl`` like an in-process sweep (nothing lost, nothing written twice).

* ``--workers N`` starts an embedded ``LocalCluster`` of N worker processes (spawned, one thread
  each unless ``--threads-per-worker``); ``--scheduler ADDRESS`` sends the jobs to a running
  cluster (``dask scheduler`` and ``dask worker`` processes on other machines).
* Timing is kept honest by Dask *resources*: a job that measures time needs ``MACHINE=1`` (``GPU=1``
  for a CUDA device), held by the workers that may time (``dask worker --resources MACHINE=1``; in
  the embedded cluster the first worker alone, unless ``--resources`` gives every worker its own).
  Error-only work (the references a sweep module lists with ``references(case)``) needs none and
  runs on every worker in parallel, all of it before the first timed job, so that no timed job
  shares its machine's cores with error-only work. Each row records its worker's host, device, threads and load
  (``machine``, ``worker``); reports group times by host and never put two hosts in one ratio.
* A job whose worker dies is run again on another (Dask reschedules it); one that killed two
  workers is recorded as failed with its error (``distributed.scheduler.allowed-failures`` = 1), as
  is one that raises (a :class:`~wsoft.errors.WsoftError` at once, anything else after one retry).
  Dask counts a worker's death against every task assigned to it, so the driver submits a timed
  job only when a unit of its resource is free: the jobs queued behind a crashing one are not
  blamed for it.
  Failed rows are left out of the report and run again by a rerun.
* References are cached by key: in ``--cache-dir`` when every worker sees that folder, and in any
  case returned to the driver, which keeps them in its own cache and hands them to the jobs.
* Jobs are grouped by scene: they are submitted scene by scene with falling priority, so a worker
  takes one scene's jobs one after another, and each worker process loads a scene and builds its
  BVH once (``scene_load_s``, ``scene_was_loaded`` on the later jobs) and compiles or loads a kernel
  module once (``compile_s``: the seconds within the job). (Dask's loose worker restrictions would
  pin a scene to a worker, but a job so pinned may land, once its worker dies, on a worker without
  the timing resource.)
"""

from __future__ import annotations

import copy
import hashlib
import importlib
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

INSTALL = "pip install 'wsoft[dist]'"
ALLOWED_FAILURES = 1  # a job that killed this many workers is run again; one more and it is recorded as failed
RETRIES = 1  # runs again after an exception other than a WsoftError
WAIT_FOR_WORKERS_S = 60.0


def check(*, workers: int | None, scheduler: str | None, resources: dict | None, threads_per_worker: int) -> None:
    """The options of a distributed sweep, before anything runs: Dask is installed, one of ``workers``
    and ``scheduler``, counts at least 1; a one-line :class:`~wsoft.errors.ParameterError` otherwise."""
    from wsoft.errors import ParameterError

    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        raise ParameterError(f"--workers and --scheduler run the sweep on Dask, which is not installed: {INSTALL}") from None
    if workers and scheduler:
        raise ParameterError("give --workers N (an embedded cluster) or --scheduler ADDRESS (a running one), not both")
    if workers is not None and workers < 1:
        raise ParameterError(f"--workers {workers}: at least 1")
    if threads_per_worker < 1:
        raise ParameterError(f"--threads-per-worker {threads_per_worker}: at least 1")
    if scheduler and resources:
        raise ParameterError("--resources declares the embedded workers' resources; a running cluster's workers declare their own "
                             "(dask worker --resources MACHINE=1)")


def parse_resources(text: str | None) -> dict | None:
    """``MACHINE=1,GPU=1`` (or space-separated, as ``dask worker --resources`` takes them) as a dict."""
    from wsoft.errors import ParameterError

    if not text:
        return None
    out = {}
    for item in text.replace(",", " ").split():
        name, _, value = item.partition("=")
        try:
            out[name] = float(value)
        except ValueError:
            raise ParameterError(f"--resources {text}: {item!r} is not NAME=NUMBER") from None
        if not name or out[name] <= 0:
            raise ParameterError(f"--resources {text}: {item!r} is not NAME=NUMBER with a positive number")
    return out


def timing_resource(case: dict) -> str:
    """The resource a job that measures time on ``case``'s device needs one of."""
    return "GPU" if str(case.get("device", "cpu")).startswith("cuda") else "MACHINE"


def job_key(sweep: str, case: dict) -> str:
    """The Dask key of ``case``'s job: the sweep, the scene and a hash of the whole case."""
    from wsoft.bench.harness import REFERENCE_VERSION, case_key

    digest = hashlib.sha256(f"{sweep}\n{REFERENCE_VERSION}\n{case_key(case)}".encode()).hexdigest()[:20]
    return f"wsoft-{sweep}-{case.get('scene', 'row')}-{digest}"


def reference_key(kw: dict) -> str:
    digest = hashlib.sha256(json.dumps(kw, sort_keys=True, default=str).encode()).hexdigest()[:20]
    return f"wsoft-reference-{kw.get('name', '')}-{digest}"


# -- on the workers ---------------------------------------------------------------------------------

_WARM: dict[tuple[str, str], tuple[float, float]] = {}  # (scene, device) -> (seconds of its load and BVH, of kernel loads among them)


_OWN_CACHE = os.environ.get("WSOFT_CACHE_DIR")  # the worker's own reference cache, where a job names none


def _setup(scenes: str | None, cache_dir: str | None) -> None:
    from wsoft.bench.harness import set_scenes_dir

    set_scenes_dir(scenes)
    if cache_dir or _OWN_CACHE:
        os.environ["WSOFT_CACHE_DIR"] = cache_dir or _OWN_CACHE
    else:
        os.environ.pop("WSOFT_CACHE_DIR", None)


def _worker() -> dict:
    try:
        from distributed import get_worker

        w = get_worker()
        return {"address": w.address, "name": str(w.name), "pid": os.getpid(), "resources": dict(w.state.total_resources)}
    except (ImportError, ValueError):  # not in a Dask worker (a job run by hand)
        return {"address": None, "name": None, "pid": os.getpid(), "resources": {}}


def _warm_scene(name, device) -> tuple[float, float, bool]:
    """Load scene ``name`` and build its BVH on ``device`` once per worker process: (the seconds that
    took, less the kernel compiles and loads among them; those; whether this process held the scene
    already). A scene that does not load is left to the job."""
    from wsoft.bench import harness
    from wsoft.errors import WsoftError
    from wsoft.parallel import compile_time
    from wsoft.scene.device import upload_scene

    if not isinstance(name, str) or not isinstance(device, str):
        return 0.0, 0.0, False
    if (name, device) in _WARM:
        return *_WARM[(name, device)], True
    t0 = time.perf_counter()
    try:
        harness.load(name).device_copy(device, upload_scene)
    except (WsoftError, OSError):
        return 0.0, 0.0, False
    t1 = time.perf_counter()
    kernels = compile_time(t0, t1)[0]
    _WARM[(name, device)] = (t1 - t0 - kernels, kernels)
    return *_WARM[(name, device)], False


def _store_reference(ref: dict) -> None:
    from wsoft.bench.harness import cache_dir

    path = cache_dir() / ref["file"]
    if not path.exists():
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(ref["data"])
        os.replace(tmp, path)


def run_reference(kw: dict, scenes: str | None, cache_dir: str | None) -> dict:
    """A reference job: :func:`~wsoft.bench.harness.reference` with ``kw``, returned as its cache file."""
    from wsoft.bench import harness

    _setup(scenes, cache_dir)
    _warm_scene(kw.get("name"), kw.get("device"))
    t0 = time.perf_counter()
    harness.reference(**kw)
    path = harness.reference_path(**kw)
    return {"file": path.name, "data": path.read_bytes(), "seconds": time.perf_counter() - t0, "worker": _worker()}


def run_job(module: str, case: dict, stem: str, quick: bool, scenes: str | None, cache_dir: str | None, *refs: dict) -> dict:
    """A row's job on a worker: the sweep module's ``run_case`` with the files it writes (pictures
    under the report's folder) returned with the row, and where and how it ran (``worker``)."""
    from wsoft.bench import harness
    from wsoft.errors import WsoftError
    from wsoft.parallel import compile_time

    _setup(scenes, cache_dir)
    for ref in refs:
        _store_reference(ref)
    info = _worker() | {"device": case.get("device"), "load_start": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None}
    scene_load_s, warm_compile_s, warm = _warm_scene(case.get("scene"), case.get("device"))
    mod = importlib.import_module(module)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="wsoft-job-") as tmp:
        try:
            row = mod.run_case(case, {"out_dir": Path(tmp), "stem": stem, "quick": quick})
        except WsoftError as exc:
            return {"error": exc.line(), "worker": info}
        files = {p.relative_to(tmp).as_posix(): p.read_bytes() for p in sorted(Path(tmp).rglob("*")) if p.is_file()}
    t1 = time.perf_counter()
    warm_s = 0.0 if warm else scene_load_s + warm_compile_s
    info |= {"scene_load_s": round(scene_load_s, 3), "scene_was_loaded": warm,
             "compile_s": round(compile_time(t0, t1)[0] + (0.0 if warm else warm_compile_s), 3), "job_s": round(t1 - t0, 3)}
    row["machine"] = harness.machine()
    row["worker"] = info
    return {"row": row, "files": files, "seconds": round(t1 - t0 + warm_s, 2)}


# -- on the driver ------------------------------------------------------------------------------------


def _embedded(n: int, threads: int, resources: dict | None):
    """A LocalCluster of ``n`` spawned worker processes; the first holds the timing resources (a
    machine and a GPU to itself), or every one holds ``resources`` when given."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=0, threads_per_worker=threads, processes=True, host="127.0.0.1", dashboard_address="127.0.0.1:0",
                           silence_logs=logging.ERROR)
    for i in range(n):
        spec = copy.deepcopy(cluster.new_spec)
        spec["options"]["resources"] = dict(resources) if resources is not None else ({"MACHINE": 1, "GPU": 1} if i == 0 else {})
        cluster.worker_spec[i] = spec
    cluster.scale(n)
    return cluster


def dashboard_text(client) -> str:
    import importlib.util

    if "dashboard" not in client.scheduler_info().get("services", {}):
        return "Dask dashboard: off (the scheduler serves none)"
    pages = "" if importlib.util.find_spec("bokeh") else f" (its pages need bokeh: {INSTALL})"
    return f"Dask dashboard: {client.dashboard_link}{pages}"


def failed_row(sweep: str, case: dict, error: str, worker: dict | None = None) -> dict:
    from wsoft.bench.harness import case_key

    row = {"key": case_key(case), "sweep": sweep, "case": case, "failed": True, "error": error,
           "finished": time.strftime("%Y-%m-%dT%H:%M:%S")}
    if worker:
        row["worker"] = worker
    return row


def run_jobs(sweep: str, module: str, todo: list[dict], ctx: dict, jsonl: Path, *, workers: int | None, scheduler: str | None,
             resources: dict | None, threads_per_worker: int = 1, scenes: str | None = None, cache_dir: str | None = None) -> int:
    """Run ``todo`` (cases of sweep ``sweep``, module ``module``) on Dask and append each row to
    ``jsonl`` as it finishes; returns the number of rows recorded as failed."""
    import dask

    config = {"distributed.scheduler.allowed-failures": ALLOWED_FAILURES, "distributed.worker.multiprocessing-method": "spawn"}
    with dask.config.set(config):
        cluster = _embedded(workers, threads_per_worker, resources) if workers else None
        try:
            return _drive(sweep, module, todo, ctx, jsonl, cluster=cluster, scheduler=scheduler, scenes=scenes, cache_dir=cache_dir,
                          n_workers=workers)
        finally:
            if cluster is not None:
                cluster.close()


def _drive(sweep, module, todo, ctx, jsonl, *, cluster, scheduler, scenes, cache_dir, n_workers) -> int:
    from distributed import Client, as_completed
    from tqdm import tqdm

    from wsoft.bench.harness import append_row, case_key, reference_path
    from wsoft.errors import ParameterError

    mod = importlib.import_module(module)
    try:
        client = Client(cluster if cluster is not None else scheduler, timeout="30s")
    except OSError as exc:
        raise ParameterError(f"--scheduler {scheduler}: no Dask scheduler answers there ({exc})") from None
    with client:
        print(dashboard_text(client), file=sys.stderr)

        def limit_failures(dask_scheduler=None, n=ALLOWED_FAILURES):  # nested: sent by value, the scheduler needs no wsoft
            dask_scheduler.allowed_failures = min(dask_scheduler.allowed_failures, n)
            return dask_scheduler.allowed_failures

        client.run_on_scheduler(limit_failures)
        try:
            client.wait_for_workers(n_workers or 1, timeout=WAIT_FOR_WORKERS_S)
        except TimeoutError:
            raise ParameterError(f"no Dask worker joined {scheduler or 'the embedded cluster'} within {WAIT_FOR_WORKERS_S:.0f} s") from None
        info = client.scheduler_info(n_workers=-1)["workers"]
        hosts = sorted({w["host"] for w in info.values()})
        print(f"{len(info)} Dask workers on {', '.join(hosts)}; {len(todo)} jobs", file=sys.stderr)
        if not todo:
            return 0
        # the jobs by scene (first appearance), each scene's jobs in the sweep's order
        order = list(dict.fromkeys(c.get("scene", "") for c in todo))
        todo = sorted(todo, key=lambda c: order.index(c.get("scene", "")))
        needed = {timing_resource(c) for c in todo}
        holders = {r: sorted(a for a, w in info.items() if w.get("resources", {}).get(r, 0) >= 1) for r in needed}
        for r, ws in holders.items():
            if not ws:
                how = f"dask worker {scheduler} --resources {r}=1" if scheduler else f"wsoft bench ... --resources {r}=1"
                raise ParameterError(f"no Dask worker declares the resource {r} that timed jobs need (give one it: {how})")
        # error-only jobs: the references, each once, all of them before the first timed job (on a shared host
        # they would take cores from it)
        refs: dict[str, object] = {}
        ref_futures = []
        references = getattr(mod, "references", None)
        for case in todo:
            for kw in (references(case) if references else []):
                k = reference_key(kw)
                if k in refs:
                    continue
                path = reference_path(**kw)
                if path.exists():  # the driver holds it: hand it to the jobs
                    refs[k] = client.scatter([{"file": path.name, "data": path.read_bytes()}], hash=False)[0]
                else:
                    refs[k] = client.submit(run_reference, kw, scenes, cache_dir, key=k, retries=RETRIES, priority=100)
                    ref_futures.append(refs[k])
        # the timed jobs, each resource's in the sweep's order, no more at a time than workers hold that resource:
        # Dask counts a worker's death against every task assigned to it, queued ones included, so a timed job is
        # submitted only when a unit of its resource is free, and a job that kills workers fails alone
        users = {k: 0 for k in refs}  # the timed jobs still to finish that need each reference
        pending: dict[str, list[tuple[int, dict, list[str]]]] = {r: [] for r in needed}
        for i, case in enumerate(todo):
            dep_keys = [reference_key(kw) for kw in (references(case) if references else [])]
            for k in dep_keys:
                users[k] += 1
            pending[timing_resource(case)].append((i, case, dep_keys))
        futures: dict[str, tuple[object, dict, list[str], str]] = {}
        running = as_completed(ref_futures)

        def submit_more() -> None:
            if any(not rf.done() for rf in ref_futures):  # a timed job never shares a machine with error-only work
                return
            workers = client.scheduler_info(n_workers=-1)["workers"].values()
            for r, queue in pending.items():
                slots = max(1, int(sum(w.get("resources", {}).get(r, 0) for w in workers)))
                busy = sum(1 for *_, res in futures.values() if res == r)
                while queue and busy < slots:
                    i, case, dep_keys = queue.pop(0)
                    f = client.submit(run_job, module, case, ctx["stem"], ctx["quick"], scenes, cache_dir, *[refs[k] for k in dep_keys],
                                      key=job_key(sweep, case), resources={r: 1}, retries=RETRIES, priority=-i)
                    futures[f.key] = (f, case, dep_keys, r)
                    running.add(f)
                    busy += 1

        submit_more()
        failed = 0
        bar = tqdm(total=len(todo), desc=f"{sweep} on Dask", unit="row", file=sys.stderr)
        for f in running:
            if f.key not in futures:  # a reference: the driver keeps it in its own cache too
                if f.status == "finished":
                    _store_reference(f.result())
                submit_more()
                continue
            _, case, dep_keys, _ = futures.pop(f.key)
            bar.update(1)
            if f.status != "finished":
                exc = f.exception()
                row = failed_row(sweep, case, f"{type(exc).__name__}: {exc}")
            else:
                out = f.result()
                if "error" in out:
                    row = failed_row(sweep, case, out["error"], out["worker"])
                else:
                    for rel, data in out["files"].items():
                        p = Path(ctx["out_dir"]) / rel
                        p.parent.mkdir(parents=True, exist_ok=True)
                        p.write_bytes(data)
                    row = out["row"]
                    row.update({"key": case_key(case), "sweep": sweep, "case": case, "finished": time.strftime("%Y-%m-%dT%H:%M:%S"),
                                "row_seconds": out["seconds"]})
            if row.get("failed"):
                failed += 1
                tqdm.write(f"row failed ({row['error']}): {case_key(case)}", file=sys.stderr)
            append_row(jsonl, row)
            f.release()
            for k in dep_keys:  # a reference no job needs any more leaves the workers' memory
                users[k] -= 1
                if users[k] == 0:
                    refs[k].release()
            submit_more()
        bar.close()
        return failed
