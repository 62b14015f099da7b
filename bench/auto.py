"""Sweep ``auto``: how well ``--technique auto`` chooses on scenes it never saw.

Rows: per frame of ``wsoft bench pareto`` (its scenes, lights, camera and size, :func:`wsoft.bench.pareto.cases`) the
light's features (:func:`wsoft.auto.features.light_features`: cheap, before any technique renders),
stored beside the pareto rows they are joined with. The report fits the model
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


def cases(quick: bool, devices: list[str]) -> list[dict]:
    from wsoft.bench import pareto

    return [{"kind": "features", "scene": c["scene"], "light": c["light"], "device": c["device"], "width": c["width"],
             "height": c["height"], "quick": quick} for c in pareto.cases(quick, devices)]


def run_case(case: dict, ctx: dict) -> dict:
    import time

    from wsoft.auto.features import light_features
    from wsoft.bench.harness import load

    scene = load(case["scene"])
    t0 = time.perf_counter()
    f = light_features(scene, case["light"], width=case["width"], height=case["height"], device=case["device"])
    return {"scene": case["scene"], "light": case["light"], "device": case["device"], "width": case["width"], "height": case["height"],
            "features": f, "features_ms": round(1e3 * (time.perf_counter() - t0), 1)}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.auto.evaluate import report_lines
    from wsoft.bench.common import report_header
    from wsoft.bench.harness import read_rows

    L = report_header("auto", rows, md, ctx)
    pareto = read_rows(md.parent / ("pareto-quick.jsonl" if ctx.get("quick") else "pareto.jsonl"))
    L += report_lines(pareto, rows, ctx)
    md.write_text("\n".join(L) + "\n")
