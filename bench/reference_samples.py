"""How far the reference's few-sample frames are from its many-sample answer: penumbra MAE of
``reference samples=N`` (N = 4, 16, 64 by default) against the same stage's 1024-sample frame
(seed 99), on the pixels where 0.01 < V_1024 < 0.99, mean and standard error over seeds.

It measures the light-sample draws of :mod:`wsoft.lightspace.samples` (the section "The
reference's samples" of ``docs/techniques.md``)::

    python -m wsoft.bench.reference_samples --seeds 20 --out mae.json
    python -m wsoft.bench.reference_samples --case city:/World/Lights/Rect:320x240 --seeds 6
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

CASES = ("contact::160x120", "city:/World/Lights/Sun:160x120", "city:/World/Lights/Rect:160x120",
         "penumbra_ramp::160x120", "box_plane::160x120")  # stage:light:WxH (no light: the stage's first)
REFERENCE_SAMPLES, REFERENCE_SEED = 1024, 99


def penumbra_mae(stage: str, light: str | None, width: int, height: int, counts: tuple[int, ...], seeds: tuple[int, ...]) -> dict:
    """{"penumbra_px": pixels compared, "N": mean MAE, "N_se": its standard error over seeds}."""
    import wsoft

    def v(n: int, seed: int) -> np.ndarray:
        return np.asarray(wsoft.render(stage, ("reference", {"samples": n, "seed": seed}), width=width, height=height, light=light).V)

    ref = v(REFERENCE_SAMPLES, REFERENCE_SEED)
    pen = (ref > 0.01) & (ref < 0.99)
    row: dict = {"penumbra_px": int(pen.sum())}
    for n in counts:
        errs = [float(np.abs(v(n, s) - ref)[pen].mean()) for s in seeds]
        row[str(n)] = float(np.mean(errs))
        row[f"{n}_se"] = float(np.std(errs, ddof=1) / np.sqrt(len(errs))) if len(errs) > 1 else 0.0
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wsoft.bench.reference_samples", description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", action="append", help="stage:light:WxH (repeatable; default: " + ", ".join(CASES) + ")")
    ap.add_argument("--samples", type=int, nargs="+", default=[4, 16, 64])
    ap.add_argument("--seeds", type=int, default=20, help="seeds 1..N")
    ap.add_argument("--out", help="write the rows as JSON")
    a = ap.parse_args(argv)
    out = {}
    for case in a.case or CASES:
        stage, light, size = case.split(":")
        w, h = (int(x) for x in size.split("x"))
        t0 = time.perf_counter()
        row = penumbra_mae(stage, light or None, w, h, tuple(a.samples), tuple(range(1, a.seeds + 1)))
        out[case] = row
        print(case, json.dumps(row), f"{time.perf_counter() - t0:.0f} s", flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
