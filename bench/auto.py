"""Sweep ``auto``: how well ``--technique auto`` chooses on scenes it never saw.

Rows: per frame of ``wsoft bench pareto`` (its scenes, lights, camera and size, :func:`wsoft.bench.pareto.cases`) the
light's features (:func:`wsoft.auto.features.light_features`: cheap, before any technique renders),
stored beside the pareto rows they are joined with, and per sequence of ``wsoft bench temporal``
(:func:`wsoft.bench.temporal.cases`) its first frame's (``source: temporal``), for the flicker model. The report fits the model
(:mod:`wsoft.auto.model`) once per bundled scene with that scene left out and lets it choose on
that scene's frames, for three budgets (the fastest setting's measured time x 1.2, x 2, x 5) and
three error targets (0.1, 0.05, 0.02), against the best fixed setting of the same rows
(:mod:`wsoft.auto.evaluate`): both predictors (log-linear, nearest scenes), regrets, predicted
against measured time and error, miss rates and the issue's targets. A choice is one of the swept
settings: its measured time and error are the pareto rows' own.
"""

from __future__ import annotations

from pathlib import Path

REPORT = "auto"
RENDERED = ("box_plane", "contact", "cutout", "penumbra_ramp")  # small stages rendered through --technique auto
RENDER_BUDGETS = (100.0, 500.0)
_METHODS: dict = {}  # (pareto rows file, its modification time, frames) -> the predictors the held-out comparison picks


def cases(quick: bool, devices: list[str]) -> list[dict]:
    from wsoft.bench import pareto

    frames = pareto.cases(quick, devices)
    out = [{"kind": "features", "scene": c["scene"], "light": c["light"], "device": c["device"], "width": c["width"],
            "height": c["height"], "quick": quick} for c in frames]
    from wsoft.bench import temporal

    out += [{"kind": "features", "source": "temporal", "scene": c["scene"], "light": c["light"], "device": c["device"], "width": c["width"],
             "height": c["height"], "frames": c["frames"], "quick": quick} for c in temporal.cases(quick, devices)]
    out += [{"kind": "render", "scene": c["scene"], "light": c["light"], "device": c["device"], "width": c["width"], "height": c["height"],
             "budget_ms": b, "quick": quick} for c in frames if c["scene"] in RENDERED for b in RENDER_BUDGETS]
    return out


def run_case(case: dict, ctx: dict) -> dict:
    if case["kind"] == "render":
        return render_case(case, ctx)
    import time

    from wsoft.auto.features import light_features
    from wsoft.bench.harness import load

    if case.get("source") == "temporal":
        from wsoft.auto.calibrate import first_time
        from wsoft.bench.harness import scene_file
        from wsoft.pipeline import load_stage

        t = first_time(case)
        scene = load_stage(scene_file(case["scene"]), time=t)
        extra = {"source": "temporal", "time": t}
    else:
        scene, extra = load(case["scene"]), {}
    t0 = time.perf_counter()
    f = light_features(scene, case["light"], width=case["width"], height=case["height"], device=case["device"])
    return {"kind": "features", "scene": case["scene"], "light": case["light"], "device": case["device"], "width": case["width"],
            "height": case["height"], **extra, "features": f, "features_ms": round(1e3 * (time.perf_counter() - t0), 1)}


def render_case(case: dict, ctx: dict) -> dict:
    """``--technique auto`` rendered on a frame of a scene the model was fitted without (its pareto and
    feature rows left out): the choice, its predicted time and its measured time (median of 3 runs
    after a warm-up, as the pareto rows measure), beside the pareto row's time of the same setting."""
    import statistics
    import tempfile
    from pathlib import Path

    import wsoft
    from wsoft.auto.evaluate import best_method, compare_methods
    from wsoft.auto.model import fit, training_frames
    from wsoft.bench.harness import load, read_rows

    out = Path(ctx["out_dir"])
    stem = "pareto-quick" if case["quick"] else "pareto"
    feats = [r for r in read_rows(out / f"{ctx['stem']}.jsonl") if r.get("kind", "features") == "features"]
    frames = training_frames(read_rows(out / f"{stem}.jsonl"), feats)
    if not any(f["scene"] == case["scene"] and f["light"] == case["light"] for f in frames):
        from wsoft.errors import ParameterError

        raise ParameterError(f"{case['scene']} {case['light']}: no pareto row with features (run wsoft bench pareto, then this sweep again)")
    src = out / f"{stem}.jsonl"
    ident = (str(src), src.stat().st_mtime_ns, len(frames))
    if ident not in _METHODS:  # the held-out comparison, once per rows file and process (it refits every scene)
        _METHODS[ident] = best_method(compare_methods(frames))
    method = _METHODS[ident]
    m = fit([f for f in frames if f["scene"] != case["scene"]], method=method)
    scene = load(case["scene"])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "held_out.json"
        m.save(path)
        kw = dict(width=case["width"], height=case["height"], light=case["light"], device=case["device"], budget_ms=case["budget_ms"], model=str(path))
        first = wsoft.render(scene, "auto", **kw)
        rec = next(iter(first.stats["counters"]["techniques"]["auto"].values()))["auto"]
        c = rec["choice"]
        fixed = dict(width=case["width"], height=case["height"], light=case["light"], device=case["device"], **c["params"])
        wsoft.render(scene, c["technique"], **fixed)
        totals, own = [], []
        for _ in range(3):  # alternating rounds: auto, then the chosen setting rendered as a fixed technique
            totals.append(wsoft.render(scene, "auto", **kw).stats["timings_ms"]["total"])
            own.append(wsoft.render(scene, c["technique"], **fixed).stats["timings_ms"]["total"])
    row = next(f for f in frames if f["scene"] == case["scene"] and f["light"] == case["light"])
    key = next(k for k, s in row["settings"].items() if s["technique"] == rec["choice"]["technique"] and s["params"] == rec["choice"]["params"])
    return {"kind": "render", "scene": case["scene"], "light": case["light"], "device": case["device"], "width": case["width"],
            "height": case["height"], "budget_ms": case["budget_ms"], "choice": rec["choice"], "warning": rec["warning"], "method": method,
            "measured_ms": statistics.median(totals), "measured_ms_runs": totals, "fixed_ms": statistics.median(own), "fixed_ms_runs": own,
            "pareto_ms": row["settings"][key]["ms"],
            "pareto_error": row["settings"][key]["error"]}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    import statistics

    from wsoft.auto.evaluate import report_lines
    from wsoft.auto.model import merge_rows
    from wsoft.bench.common import report_header
    from wsoft.bench.harness import read_rows

    L = report_header("auto", rows, md, ctx)
    pareto = read_rows(md.parent / ("pareto-quick.jsonl" if ctx.get("quick") else "pareto.jsonl"))
    seqs = read_rows(md.parent / ("temporal-quick.jsonl" if ctx.get("quick") else "temporal.jsonl"))
    modern = read_rows(md.parent / ("modern-quick.jsonl" if ctx.get("quick") else "modern.jsonl"))
    pareto, added = merge_rows(pareto, modern)  # as wsoft calibrate --modern does
    L += report_lines(pareto, [r for r in rows if r.get("kind", "features") == "features"], ctx, temporal_rows=seqs)
    L += ["", f"`modern.jsonl`: {added} of its entries joined the pareto row of their frame (those the row lacks; "
          "`wsoft calibrate --modern` adds the same)."]
    rendered = [r for r in rows if r.get("kind") == "render"]
    if rendered:
        L += ["", "## Rendered through `--technique auto` (held out)", "",
              "The same choice made in a real render: `wsoft.render(scene, \"auto\", budget_ms=B, model=...)` with the model fitted "
              "without the scene, the chosen setting's passes in the frame graph; frame ms: median of 3 runs after a warm-up (graph passes; "
              "the feature probe runs before them), in alternating rounds with the chosen setting rendered as a fixed technique "
              "(`fixed ms`), beside the model's prediction and the pareto row's time of the same setting (measured when the pareto "
              "sweep ran: `fixed ms / pareto ms` is how much slower the machine ran this sweep than that one).", "",
              "| scene | light | budget ms | choice | predicted ms | its bound | auto ms | fixed ms | auto / fixed | pareto row's ms | fixed / pareto | error (pareto row) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rendered:
            c = r["choice"]
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['budget_ms']:g} | {c['setting']}{' (warned)' if r['warning'] else ''} | "
                     f"{c['predicted_ms']:.0f} | {c['ms_bound']:.0f} | {r['measured_ms']:.0f} | {r['fixed_ms']:.0f} | "
                     f"{r['measured_ms'] / r['fixed_ms']:.2f} | {r['pareto_ms']:.0f} | {r['fixed_ms'] / r['pareto_ms']:.2f} | {r['pareto_error']:.4f} |")
        within = sum(r["measured_ms"] <= 1.1 * r["budget_ms"] for r in rendered)
        ratios = [r["measured_ms"] / r["fixed_ms"] for r in rendered]
        load = [r["fixed_ms"] / r["pareto_ms"] for r in rendered]
        L += ["", f"Rendered within the budget × 1.1 in this run: {within} of {len(rendered)}; the pareto rows' times of the same "
              f"settings: {sum(r['pareto_ms'] <= 1.1 * r['budget_ms'] for r in rendered)} of {len(rendered)}. auto / fixed: median "
              f"{statistics.median(ratios):.2f} ({min(ratios):.2f} to {max(ratios):.2f}); fixed / pareto: median "
              f"{statistics.median(load):.2f}. A budget is in the time of the machine the model's rows were measured on: a machine "
              "running slower (loaded, as in this run, or another) needs `wsoft calibrate --quick` or rows of its own."]
    md.write_text("\n".join(L) + "\n")
