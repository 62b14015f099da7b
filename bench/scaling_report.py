"""``reports/scaling.md`` from the ``scaling`` sweep's rows (:mod:`wsoft.bench.scaling`): per axis a
log-log plot of each technique's time, its fitted exponent beside the one its algorithm implies,
its exponent against the count of its own work where that is not the axis (wedge tests, triangle
and cell pairs, occluders gathered), the memory the largest point held, the stage's loading
against usd-core's read and embreex's build, and how to predict a frame's time from the fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RAY_TRACED = ("reference", "rtdenoise")  # visibility by rays through a BVH: about log n in the triangles and instances
AXES = ("triangles", "pixels", "map", "lights", "instances")
AXIS_X = {"triangles": "triangles", "pixels": "pixels", "map": "map texels", "lights": "lights", "instances": "placed instances"}
# the counter (``FrameResult.counters()``) that counts a technique's own work where the axis does not
WORK = {"dcs": ("wedge_tests", "wedge tests"), "pwedge": ("wedge_tests", "wedge tests"),
        "izb": ("triangle_cell_pairs", "triangle-cell pairs"), "ssm": ("occluders_total", "occluders gathered"),
        "rtdenoise": ("rays", "rays"), "salzman": ("caster_triangles", "caster triangles")}
MARGIN = 0.2  # a fitted exponent this far above the implied one is flagged


def size_of(row: dict) -> float:
    """The row's size on its axis: triangles, pixels (w x h), map texels (side²), lights or instances."""
    axis, v = row["axis"], row["value"]
    if axis == "pixels":
        return float(v[0] * v[1])
    if axis == "map":
        return float(v) ** 2
    if axis == "triangles":
        return float(row["triangles"])
    return float(v)


def log_exponent(xs: list[float]) -> float:
    """The exponent a cost of ``log n`` shows over the sizes ``xs`` (the slope of log log2 n on
    log n, least squares; 0 with fewer than two sizes above 1)."""
    xs = [x for x in xs if x > 1.0]
    if len(xs) < 2 or min(xs) == max(xs):
        return 0.0
    return float(np.polyfit(np.log(xs), np.log(np.log2(xs) + 1.0), 1)[0])


def implied(technique: str, axis: str, xs: list[float] | None = None) -> tuple[float, str]:
    """The exponent of time on ``axis`` that ``technique``'s algorithm implies over the sizes
    ``xs`` (those a log n cost is read over; None: log n counts as 0), and why."""
    logn = log_exponent(xs or [])
    if axis == "triangles":
        if technique in RAY_TRACED:
            return logn, "rays through a BVH: log n"
        return 1.0, "every caster triangle rasterized or turned into edges and wedges: linear"
    if axis == "instances":
        if technique in RAY_TRACED:
            return logn, "a top-level BVH over the instances: log n"
        return 1.0, "every instance in the light's view drawn: linear in instances drawn"
    if axis == "pixels":
        return 1.0, "per-pixel passes: linear in pixels (the map's passes do not grow)"
    if axis == "map":
        return (0.0, "no map") if technique in RAY_TRACED else (1.0, "per-texel passes: linear in texels")
    return 1.0, "each light's passes repeated: linear in lights"


def fit(xs: list[float], ys: list[float]) -> float | None:
    """The least-squares slope of log y on log x (None with fewer than two distinct x)."""
    if len(xs) < 2 or min(xs) == max(xs):
        return None
    return float(np.polyfit(np.log(xs), np.log(np.maximum(ys, 1e-6)), 1)[0])


def mixed_load(rows: list[dict]) -> tuple[float, float] | None:
    """(lowest, highest) load average of an axis's rows when they are read by wall time and the
    load differs by more than 2x between them (wall times at the higher load are inflated, and
    exponents across them with it), else None."""
    loads = [r["machine"]["load"] for r in rows if r.get("machine", {}).get("load") is not None]
    if timer(rows) != "ms" or not loads or max(loads) <= 2.0 * max(min(loads), 1.0):
        return None
    return min(loads), max(loads)


def timer(rows: list[dict]) -> str:
    """The time an axis's rows are read by: ``cpu_ms`` (the passes' CPU time, every thread's: steady
    on a shared machine) where every measured point has it, else ``ms`` (wall)."""
    measured = [e for r in rows for e in r.get("techniques", {}).values() if e.get("ms") is not None]
    return "cpu_ms" if measured and all(e.get("cpu_ms") is not None for e in measured) else "ms"


def points(rows: list[dict], technique: str, key: str = "ms") -> list[tuple[float, float, dict]]:
    """(size, time ``key``, the technique's entry) of the rows where ``technique`` was measured, by size."""
    return sorted(((size_of(r), r["techniques"][technique][key], r["techniques"][technique]) for r in rows
                   if technique in r.get("techniques", {}) and r["techniques"][technique].get(key) is not None), key=lambda p: p[0])


def work_exponent(technique: str, pts: list[tuple[float, float, dict]]) -> tuple[float | None, str]:
    """The exponent of ``technique``'s time on the count of its own work (:data:`WORK`) over
    ``pts``, and the count's name (None, "" where it has no such count or it does not vary)."""
    if technique not in WORK:
        return None, ""
    key, name = WORK[technique]
    ws = [(float(e.get("counters", {}).get(key) or 0.0), ms) for _, ms, e in pts]
    ws = [(w, ms) for w, ms in ws if w > 0.0]
    if len(ws) < 2 or max(w for w, _ in ws) < 2.0 * min(w for w, _ in ws):
        return None, ""  # a count that hardly varies along the axis says nothing about the time's growth
    k = fit([w for w, _ in ws], [ms for _, ms in ws])
    return k, name


def tail_exponent(pts: list[tuple[float, float, dict]]) -> float | None:
    """The slope between the two largest measured points: the growth where a frame is costly."""
    return fit([p[0] for p in pts[-2:]], [p[1] for p in pts[-2:]]) if len(pts) >= 2 else None


def exponents(rows: list[dict]) -> dict[str, dict[str, dict]]:
    """Per axis and technique: fitted, tail and implied exponents, the work exponent, the points."""
    out: dict[str, dict[str, dict]] = {}
    for axis in AXES:
        mine = sorted((r for r in rows if r.get("axis") == axis), key=size_of)
        xs = [size_of(r) for r in mine]
        key = timer(mine)
        for t in sorted({t for r in mine for t in r.get("techniques", {})}):
            pts = points(mine, t, key)
            imp, why = implied(t, axis, [p[0] for p in pts] or xs)
            k = fit([p[0] for p in pts], [p[1] for p in pts])
            wk, wname = work_exponent(t, pts)
            out.setdefault(axis, {})[t] = {"fitted": k, "tail": tail_exponent(pts), "implied": imp, "why": why, "work": wk, "timer": key,
                                           "work_name": wname, "points": pts,
                                           "over": k is not None and k > imp + MARGIN}
    return out


def predict_ms(base_ms: float, exps: dict[str, float | None], base: dict[str, float], stage: dict[str, float]) -> float:
    """A frame's technique time at ``stage``'s sizes from its time ``base_ms`` at ``base``'s: each axis
    but the lights adds what it added along its own row of the sweep, ``base_ms * ((x / x_base) ** k
    - 1)`` (a map's passes grow with the triangles, the per-pixel passes with the pixels: costs that
    add), and the whole is repeated per light, times ``lights ** k_lights`` (an axis with no
    exponent, or not given: unchanged)."""
    t = base_ms
    for axis, x in stage.items():
        k = exps.get(axis)
        if axis != "lights" and k is not None and axis in base and base[axis] > 0 and x > 0:
            t += base_ms * ((x / base[axis]) ** k - 1.0)
    k = exps.get("lights")
    if k is not None and stage.get("lights", 1.0) > 0:
        t *= (stage.get("lights", 1.0) / base.get("lights", 1.0)) ** k
    return t


def _cell(v: float | None, fmt: str = ".2f") -> str:
    return "-" if v is None else format(v, fmt)


def _plot(axis: str, mine: list[dict], ex: dict[str, dict], out_dir: Path, stem: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.palette import style

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for t, e in sorted(ex.items()):
        pts = e["points"]
        if pts:
            st = style(t)
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=st["marker"], color=st["color"], lw=1,
                      label=f"{t} ({_cell(e['fitted'])})")
    ax.set_xlabel(AXIS_X[axis] + " (log)")
    cpu = any(e.get("timer") == "cpu_ms" for e in ex.values())
    ax.set_ylabel(("technique passes, CPU ms (every thread)" if cpu else "technique passes, wall ms") + " (log)")
    ax.set_title(f"cost against {AXIS_X[axis]} (fitted exponent in brackets)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
    rel = Path("images") / stem / f"{axis}.png"
    (out_dir / rel).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out_dir / rel, dpi=110)
    plt.close(fig)
    return rel.as_posix()


def _axis_section(axis: str, mine: list[dict], ex: dict[str, dict], ctx: dict) -> list[str]:
    key = timer(mine)
    L = [f"## Against {AXIS_X[axis]}", "",
         "Times: " + ("the technique's passes' CPU ms (every thread's)." if key == "cpu_ms" else "the technique's passes' wall ms."), "",
         "| technique | " + " | ".join(f"{size_of(r):,.0f}" for r in mine)
         + " | fitted | last two | implied | own work: exponent | |",
         "|---|" + "---:|" * len(mine) + "---:|---:|---|---|---|"]
    for t, e in sorted(ex.items()):
        cells = []
        for r in mine:
            v = r["techniques"].get(t)
            if v is None:
                cells.append("")
            elif v.get(key) is not None:
                cells.append(f"{v[key]:.1f}")
            elif v.get("predicted_s") is not None:
                cells.append(f"({1e3 * v['predicted_s']:.0f})")
            else:
                cells.append("refused")
        wk = f"{e['work_name']}: {e['work']:.2f}" if e["work"] is not None else ""
        L.append(f"| {t} | " + " | ".join(cells) + f" | {_cell(e['fitted'])} | {_cell(e['tail'])} | {e['implied']:.2f} ({e['why']}) | {wk} | "
                 + ("**over**" if e["over"] else "") + " |")
    loads = [r["machine"]["load"] for r in mine if r.get("machine", {}).get("load") is not None]
    rel = _plot(axis, mine, ex, ctx["out_dir"], ctx["stem"])
    big = mine[-1]
    L += ["", f"![time against {AXIS_X[axis]}, log-log, one line per technique]({rel})", ""]
    if loads:
        L.append(f"Load average of the machine as these rows finished: {min(loads):.1f} to {max(loads):.1f} (2 cores).")
    mixed = mixed_load(mine)
    if mixed:
        L.append(f"**Caution**: these rows are read by wall time and finished at loads from {mixed[0]:.1f} to {mixed[1]:.1f}: "
                 "the times at the higher load are inflated by the machine's other work (rows that also hold CPU ms show it: "
                 + "; ".join(f"{size_of(r):,.0f}: `{t}` {e['ms']:.0f} wall / {e['cpu_ms']:.0f} CPU ms"
                             for r in mine for t, e in sorted(r["techniques"].items())[:2] if e.get("cpu_ms") is not None)
                 + "), and the exponents across them with it.")
    if axis in ("triangles", "instances") and "reference" in ex:
        pts = ex["reference"]["points"]
        rbr = [(x, e.get("counters", {}).get("receivers_ray_by_ray"), e.get("counters", {}).get("traversal")) for x, _, e in pts]
        L.append("`reference` beside its time: its traversal and the receivers whose packet gave up and went ray by ray (a packet "
                 "stops past its work budget where its rays fan out over geometry finer than its footprint), and its device "
                 "memory (the BVH and the packets' copy of it): "
                 + "; ".join(f"{x:,.0f}: {tr or '?'}" + (f", {n:,} receivers ray by ray" if n is not None else "")
                             + f", {e.get('device_bytes', 0) / 2**20:,.0f} MiB" for (x, n, tr), (_, _, e) in zip(rbr, pts)) + ".")
    if axis == "lights":
        gb = [(r["value"], np.median([v["gbuffer_ms"] for v in r["techniques"].values() if v.get("gbuffer_ms") is not None]))
              for r in mine if any(v.get("gbuffer_ms") is not None for v in r["techniques"].values())]
        if gb:
            L.append("What the frame graph shares and what it repeats: the G-buffer runs once a frame whatever the lights "
                     "(median over the techniques' renders: " + ", ".join(f"{g:.0f} ms at {n}" for n, g in gb)
                     + " lights); every technique's own passes (its maps, filters, rays) run once per light, so its time "
                     "grows with the lights as the table shows.")
    L += ["", f"Memory at the largest point ({size_of(big):,.0f} {AXIS_X[axis]}): "
          + "; ".join(f"`{t}` {e['rss_peak_mib']:,.0f} MiB peak RSS (+{e.get('rss_rise_mib', 0.0):,.0f} while it rendered), "
                      f"{e['device_bytes'] / 2**20:,.1f} MiB on the device"
                      for t, e in sorted(big["techniques"].items()) if e.get("ms") is not None and "rss_peak_mib" in e), ""]
    return L


def _loading_plot(tri: list[int], parts: dict[str, list[float]], cpu: bool, out_dir: Path, stem: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.palette import style

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for name, ys in parts.items():
        st = style(name)
        ax.loglog(tri, np.maximum(ys, 1e-4), marker=st["marker"], color=st["color"], lw=1, label=f"{name} ({_cell(fit(tri, ys))})")
    ax.set_xlabel("triangles (log)")
    ax.set_ylabel(("CPU s (every thread)" if cpu else "wall s") + " (log)")
    ax.set_title("loading against triangles (fitted exponent in brackets)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    rel = Path("images") / stem / "loading.png"
    (out_dir / rel).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out_dir / rel, dpi=110)
    plt.close(fig)
    return rel.as_posix()


def _loading_section(load: list[dict], out_dir: Path | None = None, stem: str = "scaling") -> list[str]:
    cpu = all("load_cpu_s" in r for r in load)
    sfx = "_cpu_s" if cpu else "_s"
    L = ["## Loading: the stage on disk to the first pass", "",
         "usd-core's open and read of the sheet's arrays (`Usd.Stage.Open`, the mesh's points, indices and counts), "
         "wsoft's `load_stage` (the same open, then triangulation, transforms, materials, lights: the whole of it), the "
         "device upload (the arrays and Warp's BVH build), and embreex building the same triangles (the peer: the "
         "triangles' corners gathered from the arrays usd-core read, then its `TriangleMesh`, which commits the scene). "
         + ("Seconds of CPU time (every thread's: steady on a shared machine; embreex builds on several threads), wall "
            "seconds in brackets." if cpu else "Wall seconds."), "",
         "| triangles | usd-core read s | wsoft load s | wsoft load past usd-core's read s | upload (BVH) s | embree build s | "
         "µs a triangle (load + upload) | peak RSS MiB |",
         "|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def cell(r, part):
        v = r.get(part + sfx)
        if v is None:
            return "-"
        return f"{v:.3f}" + (f" ({r[part + '_s']:.3f})" if cpu and r.get(part + "_s") is not None else "")

    for r in load:
        L.append(f"| {r['triangles']:,} | {cell(r, 'usd_read')} | {cell(r, 'load')} | {r['load' + sfx] - r['usd_read' + sfx]:.3f} | "
                 f"{cell(r, 'upload')} | {cell(r, 'embree_build')} | {1e6 * (r['load' + sfx] + r['upload' + sfx]) / r['triangles']:.2f} | "
                 f"{r['rss_peak_mib']:,.0f} |")
    tri = [r["triangles"] for r in load]
    parts = {"usd-core read": [r["usd_read" + sfx] for r in load], "wsoft load": [r["load" + sfx] for r in load],
             "upload (BVH)": [r["upload" + sfx] for r in load]}
    if all(r.get("embree_build" + sfx) is not None for r in load):
        parts["embree build"] = [r["embree_build" + sfx] for r in load]
    ks = {name: fit(tri, ys) for name, ys in parts.items()}
    if out_dir is not None and len(load) >= 2:
        L += ["", f"![loading against triangles, log-log, one line per step]({_loading_plot(tri, parts, cpu, out_dir, stem)})"]
    if any(k is not None for k in ks.values()):
        L += ["", "Exponents in the triangles (implied: 1.0, linear; a fixed cost pulls them below 1 at the small sizes): "
              + ", ".join(f"{name} {k:.2f}" for name, k in ks.items() if k is not None) + "."]
        big = load[-1]
        tot = big["load" + sfx] + big["upload" + sfx]
        if tot > 0 and big.get("embree_build" + sfx):
            L.append(f"At {big['triangles']:,} triangles: usd-core's read {100 * big['usd_read' + sfx] / tot:.0f}% of load and upload, "
                     f"wsoft's own loading past it {100 * (big['load' + sfx] - big['usd_read' + sfx]) / tot:.0f}%, the upload and BVH "
                     f"{100 * big['upload' + sfx] / tot:.0f}%; Warp's upload and BVH take {big['upload' + sfx] / big['embree_build' + sfx]:.1f}x "
                     "embreex's build of the same triangles.")
    prof = [r for r in load if r.get("load_profile")]
    if prof:
        L += ["", "Where wsoft's own loading goes (a second `load_stage` under cProfile, each function's own time as a share of "
              "the profiled total; the stage's meshes through `wsoft.scene.usd_mesh`):"]
        L += [f"* {r['triangles']:,} triangles: " + ", ".join(f"`{name}` {100 * share:.0f}%" for name, share in r["load_profile"].items())
              for r in prof]
    return L + [""]


def _prediction_section(rows: list[dict], ex: dict[str, dict[str, dict]]) -> list[str]:
    """How a user predicts a frame's technique time on a stage of their own size."""
    base_rows = [r for r in rows if r.get("axis") == "triangles" and r.get("value") == 100_000]
    if not base_rows:
        return []
    b = base_rows[0]
    base = {"triangles": float(b["triangles"]), "pixels": float(b["width"] * b["height"]), "lights": 1.0}
    L = ["## Predicting a frame's time on your own stage", "",
         f"Start from a technique's time at the base point ({b['triangles']:,} triangles, {b['width']}x{b['height']} pixels, one "
         "light, its default map), add what the triangles and the pixels each added along their own rows, and repeat the "
         "whole per light: `t = (t_base + t_base((T / T_base)^k_T - 1) + t_base((P / P_base)^k_P - 1)) x L^k_L`, with the "
         "*last two* exponents (the growth where frames are costly; the whole-range fit is pulled down by fixed costs at "
         "small sizes). Adding the two assumes the costs that grow with triangles (maps, edges) and with pixels (per-pixel "
         "passes) are apart; where they multiply (`dcs`, `pwedge`: wedges per receiver per edge) it under-predicts. It is "
         "an estimate from this one stage family (about half the frame in penumbra or umbra), not checked here against "
         "other stages; on this machine (Warp's scalar CPU backend, 2 cores); the reference at 16 samples. "
         "`wsoft.bench.scaling_report.predict_ms` does the arithmetic.", "",
         "| technique | t_base ms | k_T (triangles) | k_P (pixels) | k_L (lights) | predicted: 2M triangles, 1920x1080, 4 lights, s |",
         "|---|---:|---:|---:|---:|---:|"]
    stage = {"triangles": 2.0e6, "pixels": 1920.0 * 1080.0, "lights": 4.0}
    for t, e in sorted(b["techniques"].items()):
        if e.get("ms") is None:
            continue
        exps = {axis: ex.get(axis, {}).get(t, {}).get("tail") for axis in ("triangles", "pixels", "lights")}
        p = predict_ms(e["ms"], exps, base, stage)
        L.append(f"| {t} | {e['ms']:.0f} | {_cell(exps['triangles'])} | {_cell(exps['pixels'])} | {_cell(exps['lights'])} | "
                 f"{p / 1e3:.1f} |")
    return L + [""]


def _flag_section(ex: dict[str, dict[str, dict]], rows: list[dict]) -> list[str]:
    """Every fitted or last-two exponent above the implied one by more than :data:`MARGIN`, with
    the count of the technique's own work beside it (its cause where that count explains it)."""
    L = ["## Exponents above what the algorithm implies", ""]
    found = False
    for axis in AXES:
        mixed = mixed_load([r for r in rows if r.get("axis") == axis])
        for t, e in sorted(ex.get(axis, {}).items()):
            tail_over = e["tail"] is not None and e["tail"] > e["implied"] + MARGIN
            if not (e["over"] or tail_over):
                continue
            found = True
            what = f"fitted {_cell(e['fitted'])}" + (f", last two {_cell(e['tail'])}" if tail_over else "")
            line = f"* `{t}` against {AXIS_X[axis]}: {what}, implied {e['implied']:.2f}."
            if mixed:
                line += (f" (Its rows finished at loads from {mixed[0]:.1f} to {mixed[1]:.1f} and are read by wall time: part of "
                         "this growth may be the machine's load.)")
            if e["work"] is not None:
                key = WORK[t][0]
                counts = [(p[0], p[2].get("counters", {}).get(key)) for p in e["points"] if p[2].get("counters", {}).get(key)]
                grow = fit([x for x, _ in counts], [float(c) for _, c in counts])
                tail_grow = fit([x for x, _ in counts[-2:]], [float(c) for _, c in counts[-2:]])
                listed = " (" + ", ".join(f"{c:,} at {x:,.0f}" for x, c in counts) + ")"
                if abs(e["work"] - 1.0) <= MARGIN and grow is not None and tail_grow is not None and max(grow, tail_grow) > e["implied"] + MARGIN:
                    line += (f" Cause: its time is linear in its {e['work_name']} (exponent {e['work']:.2f}), and that count grows "
                             f"with exponent {grow:.2f} in the {AXIS_X[axis]}, {tail_grow:.2f} between the last two{listed}")
                    grid = [p[2].get("counters", {}).get("grid_size") for p in e["points"]]
                    pairs = [p[2].get("counters", {}).get("edge_bin_pairs") for p in e["points"]]
                    if any(grid):
                        from wsoft.accel.dcs_bins import MAX_PAIRS

                        line += ("; the grid it bins silhouette edges in is halved until its (cell, edge) pairs fit "
                                 f"`wsoft.accel.dcs_bins.MAX_PAIRS` ({MAX_PAIRS:,}), so it is coarser as the edges grow (cells a side: "
                                 + ", ".join(str(g) for g in grid if g) + "; pairs: " + ", ".join(f"{q:,}" for q in pairs if q)
                                 + ") and each receiver tests the edges of a larger cell: the bound is that memory cap, "
                                 "a finer grid costs memory in proportion to its pairs")
                else:
                    line += (f" Not explained by its {e['work_name']}: time on that count has exponent {e['work']:.2f}, the count on "
                             f"the {AXIS_X[axis]} {_cell(grow)}{listed}; the cause is not found by this sweep")
                line += "."
            else:
                line += " No count of its own work in the rows explains it; the cause is not found by this sweep."
            L.append(line)
    if not found:
        L.append("None.")
    return L + [""]


def write_report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = [line for line in report_header("scaling", rows, md, ctx) if not line.startswith(("Error is against", "penumbra =", "Times:"))]
    L += ["Each row varies one axis of a procedural stage (a perforated, wavy sheet over a ground under rect lights, the same "
          "covered pixels at every size) and runs in a child process of its own. A technique's time is its passes past the "
          "scene and the G-buffer (light maps, its own passes; the reference at 16 samples), the median of 3 alternating "
          "rounds after a warm-up, on Warp's scalar CPU backend. *fitted*: the least-squares exponent over every measured "
          "point; *last two*: the slope between the two largest; *implied*: the exponent its algorithm implies (log n read "
          "over the measured sizes for ray tracing); a fitted exponent more than 0.2 above it is marked **over**; *own "
          "work*: the exponent of the time against the count of the technique's own work where that is not the axis. Peak "
          "RSS is the process's (the stage, Warp's caches and every earlier technique's leftovers included); the rise is "
          "what the technique's own render added to it. A time in brackets was not measured: the technique's time "
          "extrapolated from the axis's earlier points passes 60 s there (the prediction, in ms); `refused`: the technique "
          "refuses that point (a map beyond its parameter's range, a stage it would need flattened: the reason is in the "
          "rows); an empty cell: the point was not run for it.", ""]
    ex = exponents(rows)
    for axis in AXES:
        mine = sorted((r for r in rows if r.get("axis") == axis), key=size_of)
        if mine:
            L += _axis_section(axis, mine, ex.get(axis, {}), ctx)
    L += _flag_section(ex, rows)
    L += _prediction_section(rows, ex)
    load = sorted((r for r in rows if r.get("axis") == "loading"), key=lambda r: r["triangles"])
    if load:
        L += _loading_section(load, ctx["out_dir"], ctx["stem"])
    missing = missing_rows(rows, ctx.get("cases") or [])
    if missing:
        L += ["## Rows not measured", "",
              "The sweep was stopped before these rows finished (`wsoft bench scaling` resumes them): "
              + ", ".join(f"{axis} = {value}" for axis, value in missing) + ".", ""]
    md.write_text("\n".join(L) + "\n")


def missing_rows(rows: list[dict], cases: list[dict]) -> list[tuple[str, object]]:
    """(axis, value) of the sweep's ``cases`` (:func:`wsoft.bench.scaling.cases`) that no row holds."""
    have = {(r.get("axis"), str(r.get("value")), r.get("device")) for r in rows}
    return [(c["axis"], c["value"]) for c in cases if (c["axis"], str(c["value"]), c["device"]) not in have]
