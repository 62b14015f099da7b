"""Sweep ``scaling``: how a frame's cost grows with the work, for every technique at its defaults.

One procedural stage family (:func:`sheet_stage`): a perforated, wavy sheet over a ground under
small rect lights, a camera looking down at it, the same covered pixels whatever its size. Each
row varies one axis from the base (:data:`BASE`) and runs in a child process of its own
(``python -m wsoft.bench.scaling CASE``), so its peak resident memory is its own:

* ``triangles``: the sheet from 10⁴ to 10⁷ triangles;
* ``pixels``: 160 x 120 to 1920 x 1080;
* ``map``: every map technique's map from 512² to 8192² (its ``size_param``);
* ``lights``: 1 to 64 rect lights over the sheet, each rendered (what the graph shares, the
  G-buffer, runs once);
* ``instances``: 1 to 10⁶ placed copies (a PointInstancer) of a 2,000-triangle prototype;
* ``loading``: the stage on disk (``.usdc``) to the first pass: usd-core's open and read of the
  arrays, wsoft's load (triangulation, transforms, materials), the device upload (BVH build), and
  embreex's build of the same triangles (the peer), against triangles.

In a row, every technique (the reference at 16 samples) renders once to warm up (its kernels
compile), then :data:`ROUNDS` alternating rounds over the techniques (medians); a technique's time
is its passes past the scene and the G-buffer (light maps, its own passes, the reference's), wall
and CPU (every thread's: :func:`technique_cpu_ms`, steadier on a shared machine), its memory the
device bytes its passes hold and the process's peak RSS while it rendered (Linux's ``VmHWM``,
reset before each technique through ``/proc/self/clear_refs``). A technique whose time at the
row's point, extrapolated from the axis's earlier rows (:func:`_predicted_s`), passes
:data:`BUDGET_S` is not run there (:func:`over_budget`): the row records the prediction instead.
The loading rows record wall and CPU seconds of each step. The axes run cheapest first (map sizes
last: an 8192² map per technique costs the most).

The report fits each technique's exponent per axis (the slope of log time on log size, least
squares over the measured points) beside the exponent its algorithm implies (:func:`implied`);
one more than 0.2 above it is flagged.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TRIANGLES = (10_000, 100_000, 1_000_000, 10_000_000)
PIXELS = ((160, 120), (320, 240), (640, 480), (1280, 720), (1920, 1080))
MAPS = (512, 1024, 2048, 4096, 8192)
LIGHTS = (1, 4, 16, 64)
INSTANCES = (1, 10, 100, 1_000, 10_000, 100_000, 1_000_000)
QUICK = {"triangles": (2_000, 8_000), "pixels": ((64, 48), (128, 96)), "map": (256, 512), "lights": (1, 2), "instances": (1, 16),
         "loading": (2_000, 8_000)}
BASE = {"triangles": 100_000, "width": 320, "height": 240, "lights": 1, "instances": 0, "map": None}
QUICK_BASE = {"triangles": 2_000, "width": 64, "height": 48, "lights": 1, "instances": 0, "map": None}
ROUNDS = 3
BUDGET_S = 60.0
REFERENCE_SAMPLES = 16
PROTOTYPE_TRIANGLES = 2_000
SCENE_KINDS = ("scene", "gbuffer", "shade", "resolve")  # the timings_by_kind_ms kinds that are not the technique's


def axis_values(axis: str, quick: bool) -> tuple:
    if quick:
        return QUICK[axis]
    return {"triangles": TRIANGLES, "pixels": PIXELS, "map": MAPS, "lights": LIGHTS, "instances": INSTANCES, "loading": TRIANGLES}[axis]


def cases(quick: bool, devices: list[str]) -> list[dict]:
    base = QUICK_BASE if quick else BASE
    out = []
    for dev in devices:
        for axis in ("triangles", "pixels", "loading", "lights", "instances", "map"):  # the cheapest axes first
            for v in axis_values(axis, quick):
                c = {**base, "axis": axis, "device": dev, "quick": quick}
                if axis == "pixels":
                    c["width"], c["height"] = v
                elif axis in ("triangles", "loading"):
                    c["triangles"] = v
                elif axis == "map":
                    c["map"] = v
                elif axis == "lights":
                    c["lights"] = v
                elif axis == "instances":
                    c["instances"] = v
                c["value"] = list(v) if isinstance(v, tuple) else v
                out.append(c)
    return out


# -- the stage family ---------------------------------------------------------------------------


def sheet_arrays(triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """A wavy sheet over [-2, 2]² about 1 above the ground, a square grid of cells with every fourth
    cell left out (a hole): (points ``[V, 3]``, triangles ``[T, 3]``), T close to ``triangles``."""
    k = max(2, int(round(math.sqrt(triangles / 1.5))))
    u = np.linspace(-2.0, 2.0, k + 1)
    x, y = np.meshgrid(u, u, indexing="ij")
    z = 1.0 + 0.08 * np.sin(3.0 * x) * np.cos(2.0 * y)
    pts = np.stack([x.ravel(), y.ravel(), z.ravel()], 1)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    keep = ~((i % 2 == 1) & (j % 2 == 1))
    a = (i * (k + 1) + j)[keep]
    tris = np.concatenate([np.stack([a, a + k + 1, a + k + 2], 1), np.stack([a, a + k + 2, a + 1], 1)])
    return pts, tris


def light_positions(n: int) -> list[tuple[float, float, float]]:
    """``n`` light centres on a grid 4 above the sheet (one: over its middle)."""
    side = int(math.ceil(math.sqrt(n)))
    u = np.linspace(-1.5, 1.5, side) if side > 1 else np.zeros(1)
    return [(float(u[q % side]), float(u[q // side]), 4.0) for q in range(n)]


def sheet_stage(case: dict, path: str) -> dict:
    """Write the row's stage to ``path`` (``.usdc``): ground, the sheet (or a PointInstancer of
    ``instances`` small sheets), ``lights`` rect lights, a camera looking down. Its triangle count."""
    from pxr import Sdf, UsdGeom, Vt

    from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_rect_light, make_stage

    stage = make_stage(path=path)
    add_quad(stage, "/World/Ground", (0, 0, 0), 4)
    size = 1.0 / math.sqrt(max(len(light_positions(case["lights"])), 1))
    for q, at in enumerate(light_positions(case["lights"])):
        add_rect_light(stage, f"/World/Light{q}", at, size, size)
    add_camera(stage, "/World/Camera", (0, -0.01, 7.5), (0, 0, 0))
    if case["instances"]:
        pts, tris = sheet_arrays(PROTOTYPE_TRIANGLES)
        n = int(case["instances"])
        side = int(math.ceil(math.sqrt(n)))
        pi = UsdGeom.PointInstancer.Define(stage, "/World/Sheets")
        UsdGeom.Scope.Define(stage, "/World/Sheets/Prototypes")
        add_mesh(stage, "/World/Sheets/Prototypes/Sheet", (pts / [side, side, 1.0], [3] * len(tris), tris.ravel()), True)
        pi.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Sheets/Prototypes/Sheet")])
        g = (np.arange(n) % side, np.arange(n) // side)
        cell = 4.0 / side
        pos = np.stack([-2.0 + cell * (g[0] + 0.5), -2.0 + cell * (g[1] + 0.5), np.zeros(n)], 1)
        pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(pos.astype(np.float32)))
        pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(n, np.int32)))
        tri_count = n * len(tris)
    else:
        pts, tris = sheet_arrays(case["triangles"])
        add_mesh(stage, "/World/Sheet", (pts, [3] * len(tris), tris.ravel()), True)
        tri_count = len(tris)
    stage.GetRootLayer().Save()
    return {"triangles": tri_count + 2}


# -- one row ------------------------------------------------------------------------------------


def _hwm_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_hwm() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _settings(scene, case: dict) -> list[tuple[str, str, dict]]:
    """(label, technique, params) of every technique that renders the stage's first light."""
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES

    out = []
    for name in sorted(TECHNIQUES):
        cls = TECHNIQUES[name]
        if refusal(name, scene, scene.lights[0]) is not None:
            continue
        params = {"samples": REFERENCE_SAMPLES} if name == "reference" else {}
        if case["axis"] == "map":
            if not cls.size_param:
                continue
            params[cls.size_param] = int(case["map"])
        out.append((name, name, params))
    return out


def _predicted_s(case: dict, label: str, earlier: list[dict]) -> float | None:
    """``label``'s seconds at this row's point from the axis's earlier rows (a power law through
    the last two measured points; one point: linear)."""
    pts = [(float(np.prod(r["value"])), r["techniques"][label]["ms"] / 1e3) for r in earlier
           if label in r.get("techniques", {}) and r["techniques"][label].get("ms") is not None]
    if not pts:
        return None
    x = float(np.prod(case["value"]))
    pts.sort()
    if len(pts) == 1:
        return pts[0][1] * x / pts[0][0]
    (x0, y0), (x1, y1) = pts[-2], pts[-1]
    k = math.log(max(y1, 1e-9) / max(y0, 1e-9)) / math.log(x1 / x0) if x1 > x0 else 1.0
    return y1 * (x / x1) ** max(k, 0.0)


def technique_cpu_ms(stats: dict) -> float:
    """The CPU milliseconds (every thread's) of a frame's passes past the scene and the G-buffer."""
    return float(sum(ms for name, ms in stats["cpu_ms"].items() if stats["pass_kinds"].get(name) not in SCENE_KINDS))


def over_budget(predicted_s: float | None) -> bool:
    """Is a technique's predicted time at a row (:func:`_predicted_s`: the whole frame's, every light
    of it included, as the axis's earlier rows measured it) past :data:`BUDGET_S`?"""
    return predicted_s is not None and predicted_s > BUDGET_S


def _render_row(case: dict, earlier: list[dict]) -> dict:
    import wsoft
    from wsoft.pipeline.loading import load_stage

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "sheet.usdc")
        info = sheet_stage(case, path)
        t0 = time.perf_counter()
        scene = load_stage(path, instancing="keep" if case["instances"] else "auto")
        load_s = time.perf_counter() - t0
        lights = [l.path for l in scene.lights]
        kw = dict(width=case["width"], height=case["height"], device=case["device"], light=None if len(lights) > 1 else lights[0])
        techs, skipped = [], {}
        for label, name, params in _settings(scene, case):
            pred = _predicted_s(case, label, earlier)
            if over_budget(pred):
                skipped[label] = {"ms": None, "predicted_s": round(pred, 2)}
            else:
                techs.append((label, name, params))
        runs: dict[str, list[float]] = {}
        cpu_runs: dict[str, list[float]] = {}  # the same passes' CPU time (every thread's), steadier than wall time on a shared machine
        extra: dict[str, dict] = {}
        from wsoft.errors import WsoftError

        refused = {}
        for label, name, params in list(techs):  # warm-up: compiles, and each technique's peak memory
            _reset_hwm()
            before = _hwm_mib()
            try:
                fr = wsoft.render(scene, (name, params), **kw)
            except WsoftError as exc:  # a map beyond its range, a stage it would need flattened: said in the row
                refused[label] = {"ms": None, "refused": exc.line()}
                techs.remove((label, name, params))
                continue
            kinds = fr.stats["timings_by_kind_ms"]
            cpu_runs[label] = []
            extra[label] = {"rss_peak_mib": round(_hwm_mib(), 1), "rss_rise_mib": round(_hwm_mib() - before, 1), "device_bytes": int(sum(fr.stats["memory_bytes"].values())),
                            "counters": fr.counters() if hasattr(fr, "counters") else {}}
            first = sum(v for k, v in kinds.items() if k not in SCENE_KINDS)
            runs[label] = [first] if first / 1e3 > BUDGET_S / ROUNDS else []
            if runs[label]:
                cpu_runs[label].append(technique_cpu_ms(fr.stats))
        for _ in range(ROUNDS):
            for label, name, params in techs:
                if len(runs[label]) and runs[label][0] / 1e3 > BUDGET_S / ROUNDS:
                    continue
                fr = wsoft.render(scene, (name, params), **kw)
                kinds = fr.stats["timings_by_kind_ms"]
                runs[label].append(sum(v for k, v in kinds.items() if k not in SCENE_KINDS))
                cpu_runs[label].append(technique_cpu_ms(fr.stats))
                extra[label]["gbuffer_ms"] = kinds.get("gbuffer", 0.0)
        out = {label: {"ms": float(statistics.median(v)), "runs": v, "cpu_ms": float(statistics.median(cpu_runs[label])), **extra[label]}
               for label, v in runs.items()}
        out.update(skipped)
        out.update(refused)
        return {**{k: case[k] for k in ("axis", "value", "width", "height", "lights", "instances", "device")},
                "triangles": info["triangles"], "load_s": load_s, "techniques": out}


PROFILE_TRIANGLES = 2_000_000  # loading rows up to this size also profile a second load (where its time goes)


def load_profile(path: str, top: int = 6) -> dict[str, float]:
    """Where ``load_stage(path)`` spends its time: a second load under cProfile, the ``top`` functions
    by their own time (``file:function`` -> share of the profiled total, which cProfile inflates
    for Python-heavy code alike)."""
    import cProfile
    import pstats

    from wsoft.pipeline.loading import load_stage

    prof = cProfile.Profile()
    prof.enable()
    load_stage(path)
    prof.disable()
    st = pstats.Stats(prof).stats
    total = sum(v[2] for v in st.values()) or 1.0
    own = sorted(((v[2], f"{Path(k[0]).name}:{k[2]}") for k, v in st.items()), reverse=True)[:top]
    return {name: round(sec / total, 3) for sec, name in own}


def _loading_row(case: dict) -> dict:
    """The stage on disk to the first pass, against usd-core's own read and embreex's build."""
    from pxr import Usd, UsdGeom

    from wsoft.pipeline.loading import load_stage
    from wsoft.scene.device import upload_scene

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "sheet.usdc")
        info = sheet_stage(case, path)
        t = {}
        c0 = time.process_time()
        t0 = time.perf_counter()
        stage = Usd.Stage.Open(path)
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Sheet"))
        pts = np.asarray(mesh.GetPointsAttr().Get())
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
        np.asarray(mesh.GetFaceVertexCountsAttr().Get())
        t["usd_read_s"], t["usd_read_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        c0 = time.process_time()
        t0 = time.perf_counter()
        scene = load_stage(path)
        t["load_s"], t["load_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        c0 = time.process_time()
        t0 = time.perf_counter()
        upload_scene(scene, case["device"])
        t["upload_s"], t["upload_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        if info["triangles"] <= PROFILE_TRIANGLES:
            t["load_profile"] = load_profile(path)
        try:
            from embreex import rtcore_scene as rtcs
            from embreex.mesh_construction import TriangleMesh

            c0 = time.process_time()
            t0 = time.perf_counter()
            es = rtcs.EmbreeScene()
            TriangleMesh(es, pts.astype(np.float32)[idx.reshape(-1, 3)])
            t["embree_build_s"], t["embree_build_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        except ImportError:
            t["embree_build_s"] = None
        return {"axis": "loading", "value": case["value"], "device": case["device"], "triangles": info["triangles"], **t,
                "rss_peak_mib": round(_hwm_mib(), 1)}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.scaling_report import write_report

    devices = sorted({r["device"] for r in rows if "device" in r}) or ["cpu"]
    write_report(rows, md, ctx | {"cases": cases(bool(ctx.get("quick")), devices)})


def run_case(case: dict, ctx: dict) -> dict:
    """Run ``case`` in a child process (its own peak memory), the axis's earlier rows beside it."""
    from wsoft.bench.harness import read_rows

    jsonl = Path(ctx["out_dir"]) / f"{ctx['stem']}.jsonl"
    earlier = [r for r in (read_rows(jsonl) if jsonl.exists() else []) if r.get("axis") == case["axis"] and r.get("device") == case["device"]]
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump({"case": case, "earlier": earlier}, f)
    try:
        proc = subprocess.run([sys.executable, "-m", "wsoft.bench.scaling", f.name], capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    if proc.returncode != 0:
        from wsoft.errors import WsoftError

        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        raise WsoftError(f"scaling row {case['axis']}={case['value']} failed: {tail[0]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(arg: str) -> None:
    with open(arg) as f:
        job = json.load(f)
    case = job["case"]
    row = _loading_row(case) if case["axis"] == "loading" else _render_row(case, job["earlier"])
    print(json.dumps(row))


if __name__ == "__main__":
    main(sys.argv[1])
