"""``wsoft calibrate``: the auto model rebuilt for a machine.

* From sweep rows (``--rows``: ``wsoft bench pareto``'s, measured on the user's own machine; with
  ``--modern``, ``wsoft bench modern``'s entries the pareto row of the same frame lacks; with
  ``--temporal``, ``wsoft bench temporal``'s sequences for the flicker model): each frame's
  features are read from ``--features`` (rows of ``wsoft bench auto``) and computed where that
  file has none, both predictors are compared scene by scene held out (:mod:`wsoft.auto.evaluate`),
  each quantity (time, error, ꟻLIP; the flicker model's time and flicker) gets the closer one, and
  the model is fitted to every frame.
* Quick (``--quick``): no sweep; one small frame (:data:`QUICK_STAGE`, :data:`QUICK_SIZE`) is
  rendered with a few settings the model knows, and the ratio of their measured to predicted
  times (median) scales the model's times (:func:`quick_scale`): the CPU model on a device kind
  without a model of its own, or the model of the kind on a machine faster or slower than the one
  its rows came from.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

QUICK_STAGE = "box_plane"
QUICK_SIZE = (160, 120)
QUICK_SETTINGS = ('hard{"shadow_map_size": 1024}', 'pcss{"shadow_map_size": 1024}', 'pcf{"shadow_map_size": 1024}')
_SCALES: dict = {}


def first_time(row: dict) -> float | None:
    """The first time code of a sequence row (``wsoft bench temporal``'s), None for a single frame's."""
    from wsoft.params import parse_frames

    if "cost" in row and row["cost"].get("time_codes"):
        return float(row["cost"]["time_codes"][0])
    frames = (row.get("case") or {}).get("frames") or row.get("frames")
    return float(parse_frames(frames)[0]) if isinstance(frames, str) else None


def frame_features(rows: list[dict], device: str = "cpu", sweep: str | None = None) -> list[dict]:
    """Features of every frame of ``rows`` (their scene, light and size; a sequence's at its first
    time code), as ``wsoft bench auto`` stores them (``sweep``: ``temporal`` for sequences' rows, stored as ``source``)."""
    from wsoft.auto.features import light_features
    from wsoft.pipeline import load_stage
    from wsoft.usd_scenes import resolve

    out, scenes = [], {}
    for r in rows:
        t = first_time(r) if sweep == "temporal" else None
        if (r["scene"], t) not in scenes:
            scenes[(r["scene"], t)] = load_stage(resolve(r["scene"]), time=t)  # a bundled stage's name, or a path
        f = light_features(scenes[(r["scene"], t)], r["light"], width=r["width"], height=r["height"], device=device)
        out.append({"kind": "features", "scene": r["scene"], "light": r["light"], "features": f, **({"source": sweep, "time": t} if sweep else {})})
    return out


def missing_features(rows: list[dict], features: list[dict], sweep: str | None, device: str) -> list[dict]:
    """``features`` and those of the frames of ``rows`` it lacks (computed)."""
    have = {(f["scene"], f["light"]) for f in features if "features" in f and (f.get("source") == "temporal") == (sweep == "temporal")}
    todo = [r for r in rows if (r["scene"], r["light"]) not in have]
    return features + (frame_features(todo, device, sweep) if todo else [])


def model_from_rows(rows: list[dict], features: list[dict], *, device_kind: str = "cpu", source: dict | None = None,
                    pixel_exp: float = 1.0, temporal: list[dict] | None = None, modern: list[dict] | None = None):
    """The model fitted to every frame of ``rows`` (with ``modern``'s entries merged in, joined with
    ``features``), each quantity by the predictor that is closer held out, and its flicker model
    fitted to ``temporal``'s moving sequences; (model, the comparison :func:`wsoft.auto.evaluate.compare_methods` gave)."""
    from wsoft.auto.evaluate import best_method, compare_methods
    from wsoft.auto.model import SEQUENCE_QUANTITIES, fit, merge_rows, temporal_frames, training_frames

    added = 0
    if modern:
        rows, added = merge_rows(rows, modern)
    frames = training_frames(rows, features)
    results = compare_methods(frames)
    method = best_method(results)
    src = dict(source or {}, frames=len(frames), scenes=sorted({f["scene"] for f in frames}), modern_entries_added=added,
               held_out={f"{t}/{e}": {k: round(v, 4) for k, v in r["prediction"].items() if k.endswith("_log")} for (t, e), r in results.items()})
    m = fit(frames, device_kind=device_kind, method=method, source=src, pixel_exponent=pixel_exp)
    tframes = temporal_frames(temporal or [], features)
    if len(tframes) >= 2:
        tres = compare_methods(tframes, SEQUENCE_QUANTITIES)
        tm = fit(tframes, device_kind=device_kind, method=best_method(tres), pixel_exponent=pixel_exp, quantities=SEQUENCE_QUANTITIES,
                 source={"frames": len(tframes), "scenes": sorted({f["scene"] for f in tframes}),
                         "held_out": {f"{t}/{e}": {k: round(v, 4) for k, v in r["prediction"].items() if k.endswith("_log")} for (t, e), r in tres.items()}})
        m.data["flicker"] = tm.data
    return m, results


def _timed(scene, technique: str, params: dict, w: int, h: int, light: str, device: str, runs: int = 3) -> float:
    """The median of ``runs`` render times (ms) after a warm-up render."""
    from wsoft.pipeline import render

    render(scene, technique, width=w, height=h, light=light, device=device, **params)
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        render(scene, technique, width=w, height=h, light=light, device=device, **params)
        ts.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(ts)


PIXEL_SIZES = ((160, 120), (320, 240))


def pixel_exponent(device: str = "cpu") -> float:
    """How frame time grows with the frame's pixels on ``device``: the median over
    :data:`QUICK_SETTINGS` of log(t(320x240) / t(160x120)) / log 4 on :data:`QUICK_STAGE`, timed in
    alternating rounds (clamped to [0, 1.5])."""
    import math

    from wsoft.pipeline import load_stage
    from wsoft.usd_scenes import resolve

    scene = load_stage(resolve(QUICK_STAGE))
    light = scene.lights[0].path
    out = []
    for k in QUICK_SETTINGS:
        name, params = k.split("{", 1)
        import json

        params = json.loads("{" + params)
        t = [_timed(scene, name, params, w, h, light, device) for w, h in PIXEL_SIZES]
        t = [(a + b) / 2 for a, b in zip(t, [_timed(scene, name, params, w, h, light, device) for w, h in reversed(PIXEL_SIZES)][::-1])]
        out.append(math.log(t[1] / t[0]) / math.log(4.0))
    return float(min(max(statistics.median(out), 0.0), 1.5))


def quick_scale(model, device: str) -> float:
    """Measured over predicted frame time (median over :data:`QUICK_SETTINGS` the model knows) of
    :data:`QUICK_STAGE` at :data:`QUICK_SIZE` on ``device`` (each rendered once to warm up, then
    timed once); once per process and device."""
    key = (id(model.data), device)
    if key in _SCALES:
        return _SCALES[key]
    from wsoft.auto.features import light_features
    from wsoft.pipeline import load_stage
    from wsoft.usd_scenes import resolve

    scene = load_stage(resolve(QUICK_STAGE))
    light = scene.lights[0]
    w, h = QUICK_SIZE
    f = light_features(scene, light, width=w, height=h, device=device)
    ratios = []
    unscaled = model.scaled(1.0 / model.scale)
    for k in QUICK_SETTINGS:
        if k not in model.data["settings"]:
            continue
        s = model.data["settings"][k]
        ratios.append(_timed(scene, s["technique"], s["params"], w, h, light.path, device, runs=1) / unscaled.predict(f, k)[0])
    _SCALES[key] = statistics.median(ratios) if ratios else 1.0
    return _SCALES[key]


def read_rows(path: Path) -> list[dict]:
    """The rows of a sweep's JSON-lines file (a line that is not JSON, such as a partial last one, is left out)."""
    import json

    out = []
    for line in Path(path).read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out


def calibrate(*, rows: str | None = None, features: str | None = None, quick: bool = False, device: str = "cpu", out: str | None = None,
              temporal: str | None = None, modern: str | None = None) -> tuple[Path, str]:
    """Write a model (see the module's docstring) to ``out`` (default the package's for the device's
    kind); (its path, a line saying what was done)."""
    from wsoft.auto.model import device_kind, load_model, model_path
    from wsoft.errors import ParameterError

    kind = device_kind(device)
    dest = Path(out) if out else model_path(kind)
    if quick:
        m, note = load_model(device=device)
        base = m.scaled(1.0 / m.scale)
        scale = quick_scale(base, device)
        m = base.scaled(scale)
        m.data["device_kind"] = kind
        m.data.setdefault("source", {})["quick_calibration"] = {"stage": QUICK_STAGE, "size": list(QUICK_SIZE), "device": device, "scale": round(scale, 4)}
        m.save(dest)
        return dest, f"times scaled by {scale:.3g} (measured / predicted on {QUICK_STAGE} {QUICK_SIZE[0]}x{QUICK_SIZE[1]}, {device})" + (f"; {note}" if note else "")
    if not rows:
        raise ParameterError("calibrate: give --rows (a pareto sweep's rows) or --quick")
    pr = read_rows(Path(rows))
    if not pr:
        raise ParameterError(f"calibrate: {rows}: no rows")
    tr = read_rows(Path(temporal)) if temporal else []
    if temporal and not tr:
        raise ParameterError(f"calibrate: {temporal}: no rows")
    mr = read_rows(Path(modern)) if modern else []
    fr = [r for r in read_rows(Path(features)) if "features" in r] if features else []
    fr = missing_features(pr, fr, None, device)
    if tr:
        fr = missing_features(tr, fr, "temporal", device)
    px = pixel_exponent(device)
    m, results = model_from_rows(pr, fr, device_kind=kind, pixel_exp=px, temporal=tr, modern=mr,
                                 source={"rows": Path(rows).name, "features": Path(features).name if features else "computed",
                                         "temporal": Path(temporal).name if temporal else None, "modern": Path(modern).name if modern else None,
                                         "pixel_exponent": {"stage": QUICK_STAGE, "sizes": [list(s) for s in PIXEL_SIZES], "settings": list(QUICK_SETTINGS)}})
    m.save(dest)
    fm = m.flicker
    return dest, (f"fitted to {len(m.data['frames'])} frames ({len(m.data['settings'])} settings): time by {m.method['time']}, "
                  f"error by {m.method['error']}, ꟻLIP by {m.method['flip']}; "
                  + (f"flicker model fitted to {len(fm.data['frames'])} moving sequences ({len(fm.data['settings'])} settings), flicker by "
                     f"{fm.method['flicker']}; " if fm else "no flicker model (give --temporal); ")
                  + (f"{m.data['source']['modern_entries_added']} entries of {modern} added; " if modern else "")
                  + f"frame time ~ pixels ** {px:.2f} (measured on {QUICK_STAGE})")
