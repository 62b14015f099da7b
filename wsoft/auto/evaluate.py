"""Leave-one-scene-out evidence for ``--technique auto``: per bundled scene, the model is fitted
without it (:func:`wsoft.auto.model.fit`) and chooses on that scene's frames (:func:`wsoft.auto.choose.pick`)
among the settings the sweep measured there; the choice's time and error are the measured ones
of the same rows, compared with the best fixed setting of those rows. ``wsoft bench auto`` writes
it into ``reports/auto.md``; ``wsoft calibrate`` picks each quantity's predictor by it."""

from __future__ import annotations

import math
import statistics

from wsoft.auto.model import (FLOORS, FRAME_QUANTITIES, MARGIN, METHODS, SEQUENCE_QUANTITIES, X_OF, fit, measured, pick, setting_text,
                              temporal_frames, training_frames)

BUDGET_FACTORS = (1.2, 2.0, 5.0)  # budgets: the frame's fastest measured setting's time times these
TARGETS = (0.1, 0.05, 0.02)  # error targets
BUDGET_SLACK = 1.1  # a choice is within budget when its measured time is at most the budget times this
TABLE_BUDGETS = (100.0, 500.0)
TABLE_TARGET = 0.02
FLIP_TARGETS = (0.02, 0.01, 0.005)  # mean ꟻLIP targets (pareto rows' error.flip)
FLICKER_TARGETS = (0.01, 0.003, 0.001)  # flicker targets (temporal rows)
GOALS = {"error_regret": 0.01, "within_budget": 0.9, "time_regret": 0.25}


def _median(xs):
    return statistics.median(xs) if xs else float("nan")


def held_out(frames: list[dict], method: dict, quantities: tuple = FRAME_QUANTITIES) -> list[dict]:
    """Per frame, the predictions of the model fitted without its scene: ``{"frame": f, "pq": {key:
    {quantity: value}}, "spread": {key: {quantity: spread}}}`` (the settings the model predicts
    ``quantities[1]`` for)."""
    out = []
    second = quantities[1]
    for s in sorted({f["scene"] for f in frames}):
        train = [f for f in frames if f["scene"] != s]
        m = fit(train, method=method, quantities=quantities)
        known = m.data["settings"]
        for f in frames:
            if f["scene"] == s:
                keys = [k for k in f["settings"] if k in known and f"{second}_coef" in known[k]]
                pq = {k: {q: m.predict_q(f["features"], k, q) for q in quantities if f"{q}_coef" in known[k]} for k in keys}
                out.append({"frame": f, "pq": pq,
                            "spread": {k: {q: known[k][f"{q}_spread"] for q in pq[k]} for k in keys}})
    return out


MARGINS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)  # the margins the report compares


def scale_known(held: list[dict]) -> list[dict]:
    """``held`` with each frame's predicted times multiplied by the median ratio of its measured to
    predicted times (an oracle: it bounds what a model of the scene's overall cost could give)."""
    out = []
    for h in held:
        r = statistics.median([math.log(h["frame"]["settings"][k]["ms"] / v["time"]) for k, v in h["pq"].items()]) if h["pq"] else 0.0
        pq = {k: dict(v, time=v["time"] * math.exp(r)) for k, v in h["pq"].items()}
        out.append(dict(h, pq=pq))
    return out


def pooled_held_out(frames: list[dict], names: tuple, ridge: float = 1.0) -> list[dict]:
    """:func:`held_out`'s predictions (time and error) with each setting's log time from one ridge fit
    per technique instead of one per setting: an intercept per setting and slopes on ``names``
    shared by the technique's settings (more frames per slope, fewer coefficients). A time model
    the report compares with the shipped one; the error is the shipped model's."""
    import numpy as np

    out = []
    for s in sorted({f["scene"] for f in frames}):
        train = [f for f in frames if f["scene"] != s]
        m = fit(train, quantities=("time", "error"))
        known = m.data["settings"]
        groups: dict = {}
        for k, st in known.items():
            groups.setdefault(st["technique"], []).append(k)
        coef, spread = {}, {}
        for keys in groups.values():
            X, y = [], []
            for f in train:
                z = m._z(f["x"], names)
                for j, k in enumerate(keys):
                    if k in f["settings"]:
                        X.append(np.concatenate([np.eye(len(keys))[j], z]))
                        y.append(math.log(max(f["settings"][k]["ms"], FLOORS["time"])))
            X, y = np.array(X), np.array(y)
            R = np.diag([0.0] * len(keys) + [ridge] * len(names))
            c = np.linalg.solve(X.T @ X + R + 1e-9 * np.eye(X.shape[1]), X.T @ y)
            sd = max(float(np.sqrt(np.sum((y - X @ c) ** 2) / max(len(y) - X.shape[1], 1))), 0.1)
            for j, k in enumerate(keys):
                coef[k], spread[k] = (c[j], c[len(keys):]), sd
        for f in frames:
            if f["scene"] == s:
                z = m._z(f["x"], names)
                keys = [k for k in f["settings"] if k in known]
                pq = {k: {"time": math.exp(coef[k][0] + coef[k][1] @ z), "error": m.predict_q(f["features"], k, "error")} for k in keys}
                out.append({"frame": f, "pq": pq, "spread": {k: {"time": spread[k], "error": known[k]["error_spread"]} for k in keys}})
    return out


def _goals(f: dict, fastest: float) -> list[tuple]:
    """(kind, name, value, quantity) of every goal a frame is tried with."""
    if f["metric"] == "flicker":
        return [("flicker_target", f"flicker {v:g}", v, "flicker") for v in FLICKER_TARGETS]
    goals = [("budget", f"fastest x {x:g}", fastest * x, "error") for x in BUDGET_FACTORS] + [("target", f"error {e:g}", e, "error") for e in TARGETS]
    goals += [("flip_target", f"ꟻLIP {v:g}", v, "flip") for v in FLIP_TARGETS]
    goals += [("table_budget", f"{b:g} ms", b, "error") for b in TABLE_BUDGETS] + [("table_target", f"error {TABLE_TARGET:g}", TABLE_TARGET, "error")]
    return goals


def cases(held: list[dict], margin: float | dict = MARGIN) -> list[dict]:
    """Every (frame, goal) of the evidence: the choice (its predicted and measured time and error,
    or ꟻLIP, or flicker) and the best fixed setting measured on the frame for the same goal.
    ``margin``: one for every setting, or per technique (a dict; a technique it lacks: :data:`MARGIN`)."""
    out = []
    for h in held:
        f, pq = h["frame"], h["pq"]
        if not pq:
            continue
        mz = (lambda k: margin.get(f["settings"][k]["technique"], MARGIN)) if isinstance(margin, dict) else (lambda k: margin)
        fastest = min(f["settings"][k]["ms"] for k in pq)
        for kind, name, v, q in _goals(f, fastest):
            keys = [k for k in pq if q in pq[k] and measured(f["settings"][k], q) is not None]
            if not keys:
                continue
            bounds = {k: (pq[k]["time"], pq[k][q], pq[k]["time"] * math.exp(mz(k) * h["spread"][k]["time"]),
                          pq[k][q] * math.exp(mz(k) * h["spread"][k][q])) for k in keys}
            meas = {k: (f["settings"][k]["ms"], measured(f["settings"][k], q)) for k in keys}
            budget = kind.endswith("budget")
            goal = "budget_ms" if budget else {"error": "target_error", "flip": "target_flip", "flicker": "target_flicker"}[q]
            key, _, warning = pick(bounds, **{goal: v})
            t, e = meas[key]
            c = {"scene": f["scene"], "light": f["light"], "metric": f["metric"] if q == "error" else q, "kind": kind, "goal": name, "value": v,
                 "choice": key, "setting": setting_of(f, key), "pred_ms": pq[key]["time"], "pred_error": pq[key][q], "ms": t, "error": e,
                 "warned": bool(warning)}
            if budget:
                within = [k for k, (tt, _) in meas.items() if tt <= v]
                best = min(within, key=lambda k: (meas[k][1], meas[k][0], k)) if within else min(meas, key=lambda k: (meas[k][0], k))
                c.update(best=setting_of(f, best), best_ms=meas[best][0], best_error=meas[best][1], error_regret=e - meas[best][1],
                         within=t <= v * BUDGET_SLACK)
            else:
                reach = [k for k, (_, ee) in meas.items() if ee <= v]
                best = min(reach, key=lambda k: (meas[k][0], k)) if reach else None
                c.update(best=setting_of(f, best) if best else None, best_ms=meas[best][0] if best else None,
                         best_error=meas[best][1] if best else None, time_regret=(t / meas[best][0] - 1.0) if best else None, reached=e <= v)
            out.append(c)
    return out


def setting_of(frame: dict, key: str) -> str:
    s = frame["settings"][key]
    return setting_text(s["technique"], s["params"])


def prediction_error(held: list[dict], quantity: str | None = None) -> dict:
    """Median |log(predicted / measured)| of time and error (``quantity``: of it, e.g. ``flip``,
    instead of the error) over every held-out setting, and the fraction of settings whose predicted
    time is within a factor 1.5 of the measured."""
    lt, le = [], []
    for h in held:
        for k, v in h["pq"].items():
            s = h["frame"]["settings"][k]
            q = quantity or ("flicker" if h["frame"]["metric"] == "flicker" else "error")
            lt.append(abs(math.log(v["time"] / s["ms"])))
            if q in v and measured(s, q) is not None:
                fl = FLOORS[q]
                le.append(abs(math.log(max(v[q], fl) / max(measured(s, q), fl))))
    return {"time_log": _median(lt), "error_log": _median(le), "time_within_1.5": sum(x <= math.log(1.5) for x in lt) / max(len(lt), 1), "n": len(lt)}


def summary(cs: list[dict]) -> dict:
    b = [c for c in cs if c["kind"] == "budget"]
    t = [c for c in cs if c["kind"] == "target"]
    tr = [c["time_regret"] for c in t if c["time_regret"] is not None]
    return {"budget_cases": len(b), "within_budget": sum(c["within"] for c in b) / max(len(b), 1),
            "error_regret_median": _median([c["error_regret"] for c in b]),
            "error_regret_p90": _quantile([c["error_regret"] for c in b], 0.9),
            "budget_warned": sum(c["warned"] for c in b), "target_cases": len(t), "target_reachable": len(tr),
            "time_regret_median": _median(tr), "time_regret_p90": _quantile(tr, 0.9),
            "target_missed": sum(not c["reached"] for c in t if c["best"] is not None),
            "target_warned": sum(c["warned"] for c in t)}


def target_summary(cs: list[dict], kind: str) -> dict:
    """For targets of ``kind`` (``flip_target``, ``flicker_target``): cases, how many some setting
    reaches, the fraction of those the choice reaches (measured), the time regrets."""
    t = [c for c in cs if c["kind"] == kind]
    reach = [c for c in t if c["best"] is not None]
    tr = [c["time_regret"] for c in reach]
    return {"cases": len(t), "reachable": len(reach), "met": sum(c["reached"] for c in reach) / max(len(reach), 1),
            "met_all": sum(c["reached"] for c in t), "time_regret_median": _median(tr), "time_regret_p90": _quantile(tr, 0.9),
            "warned": sum(c["warned"] for c in t)}


def _quantile(xs, q):
    if not xs:
        return float("nan")
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))]


def compare_methods(frames: list[dict], quantities: tuple = FRAME_QUANTITIES) -> dict:
    """Per predictor pair (time, the other quantities), the held-out predictions' accuracy
    (``<quantity>_log``: its median |log ratio|) and the choices' summary."""
    out = {}
    for mt in METHODS:
        for me in METHODS:
            method = {"time": mt, **{q: me for q in quantities[1:]}}
            held = held_out(frames, method, quantities)
            cs = cases(held)
            pred = prediction_error(held)
            pred.update({f"{q}_log": prediction_error(held, q)["error_log"] for q in quantities[1:]})
            out[(mt, me)] = {"method": method, "prediction": pred, "summary": summary(cs), "cases": cs, "held": held}
    return out


def best_method(results: dict) -> dict:
    """Per quantity, the predictor whose held-out predictions are closer (median |log ratio|, the time's or the others' predictor log-linear)."""
    qs = [q for q in next(iter(results.values()))["method"] if q != "time"]
    out = {"time": min(METHODS, key=lambda m: results[(m, "loglinear")]["prediction"]["time_log"])}
    for q in qs:
        out[q] = min(METHODS, key=lambda m: results[("loglinear", m)]["prediction"][f"{q}_log"])
    return out


def flip_flicker_lines(chosen: dict, method: dict, frames: list[dict], tframes: list[dict]) -> list[str]:
    """The report's section on ꟻLIP and flicker targets (held out)."""
    L = ["## ꟻLIP and flicker targets (leave-one-scene-out)", "",
         f"ꟻLIP: the pareto rows' mean ꟻLIP of the frame (`error.flip`), predicted per setting like the error (by **{method['flip']}**, "
         "the closer held out: the table of predictors below). Flicker: a second model, fitted to the moving sequences of "
         "`temporal.jsonl` (their first frame's features; each setting's median frame time and its flicker over the sequence), "
         "held out sequence by sequence; its candidates are the settings with flicker rows only (a technique without them is not a "
         "candidate, and `wsoft plan` says so). The still sequence (`ramp_static`) is left out of the flicker fit: a frame's "
         "features cannot tell it from `ramp_slide`, and only stochastic techniques flicker there.", "",
         "| target | cases | some setting reaches it | the choice reaches it (measured) | median time regret | 90th percentile |", "|---|---|---|---|---|---|"]
    fc = chosen["cases"]
    for v in FLIP_TARGETS:
        ts = target_summary([c for c in fc if c["value"] == v], "flip_target")
        L.append(f"| ꟻLIP {v:g} | {ts['cases']} | {ts['reachable']} | {ts['met']:.0%} ({ts['met_all']}) | {ts['time_regret_median']:.1%} | "
                 f"{ts['time_regret_p90']:.1%} |")
    ts = target_summary(fc, "flip_target")
    L.append(f"| every ꟻLIP target | {ts['cases']} | {ts['reachable']} | {ts['met']:.0%} ({ts['met_all']}) | {ts['time_regret_median']:.1%} | "
             f"{ts['time_regret_p90']:.1%} |")
    tcs = []
    if len(tframes) >= 2:
        tres = compare_methods(tframes, SEQUENCE_QUANTITIES)
        tm = best_method(tres)
        tch = tres[(tm["time"], tm["flicker"])]
        tcs = tch["cases"]
        for v in FLICKER_TARGETS:
            ts = target_summary([c for c in tcs if c["value"] == v], "flicker_target")
            L.append(f"| flicker {v:g} | {ts['cases']} | {ts['reachable']} | {ts['met']:.0%} ({ts['met_all']}) | {ts['time_regret_median']:.1%} | "
                     f"{ts['time_regret_p90']:.1%} |")
        ts = target_summary(tcs, "flicker_target")
        L.append(f"| every flicker target | {ts['cases']} | {ts['reachable']} | {ts['met']:.0%} ({ts['met_all']}) | {ts['time_regret_median']:.1%} | "
                 f"{ts['time_regret_p90']:.1%} |")
        L += ["", "Regret: the choice's measured time over the fastest setting measured to reach the target, minus 1 (negative where "
              "the choice missed the target with a faster setting). The flicker model "
              f"({len(tframes)} moving sequences: {', '.join(f['scene'] for f in tframes)}; each held-out fit sees {len(tframes) - 1}): time by "
              f"**{tm['time']}**, flicker by **{tm['flicker']}**, the closer held out:", "",
              "| time by | flicker by | time: median abs log ratio | flicker: median abs log ratio | targets met |", "|---|---|---|---|---|"]
        for (mt, me), r in tres.items():
            p, ts = r["prediction"], target_summary(r["cases"], "flicker_target")
            L.append(f"| {mt} | {me} | {p['time_log']:.3f} (×{math.exp(p['time_log']):.2f}) | {p['flicker_log']:.3f} (×{math.exp(p['flicker_log']):.2f}) | "
                     f"{ts['met_all']} of {ts['cases']} |")
        L += ["", "With so few sequences the flicker model is a coarse one: held-out flicker predictions are off by the factor above at "
              "the median, since each sequence's flicker level (the sun over a city, a rect light over a ramp) is unlike the others'. "
              "A flicker target is a request to rank settings by their measured flicker on similar scenes, not a guarantee.", ""]
    else:
        L += ["", "No flicker model: `temporal.jsonl` has fewer than two moving sequences with features.", ""]
    L += ["Every flicker and ꟻLIP choice (held out):", "", "| scene | light | target | choice | predicted ms | measured ms | predicted | measured | fastest reaching it | its ms |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for c in [c for c in fc if c["kind"] == "flip_target"] + [c for c in tcs if c["kind"] == "flicker_target"]:
        flag = "" if c["reached"] or c["best"] is None else " ✗"
        L.append(f"| {c['scene']} | {c['light'].split('/')[-1]} | {c['goal']} | {c['setting']}{flag} | {c['pred_ms']:.0f} | {c['ms']:.0f} | "
                 f"{c['pred_error']:.4f} | {c['error']:.4f} | {c['best'] or '-'} | " + ("-" if c["best_ms"] is None else f"{c['best_ms']:.0f}") + " |")
    L += ["", "✗: above the target, measured.", ""]
    return L


def report_lines(pareto_rows: list[dict], feature_rows: list[dict], ctx: dict, temporal_rows: list[dict] | None = None) -> list[str]:
    frames = training_frames(pareto_rows, feature_rows)
    if not frames:
        return ["No pareto rows with features: run `wsoft bench pareto` first (its rows are what the model learns from)."]
    results = compare_methods(frames)
    method = best_method(results)
    chosen = results[(method["time"], method["error"])]
    cs, s = chosen["cases"], chosen["summary"]
    scenes = sorted({f["scene"] for f in frames})
    L = [f"Training data: the {len(frames)} frames of `pareto.jsonl` ({len(scenes)} scenes; every technique's swept settings, "
         f"{sum(len(f['settings']) for f in frames)} (setting, frame) pairs) joined with each frame's features (this sweep's rows: "
         "computed before rendering, `wsoft.auto.features`). Every number below is **leave-one-scene-out**: the model is fitted "
         "without the scene it chooses for. A choice is one of the swept settings, so its *measured* time and error are the "
         "pareto rows' own (nothing is rendered again); the best fixed setting is the best of the same rows. Error: penumbra MAE "
         "(the MAE over all covered pixels for a point light, whose reference has no penumbra, as in pareto.md).", "",
         f"Predictors: time by **{method['time']}**, error by **{method['error']}** (each the one with the smaller held-out "
         "prediction error below; `wsoft calibrate` picks the same way).", ""]
    L += ["## What auto picks, per scene (held out of the fit)", "",
          f"| scene | light | at {TABLE_BUDGETS[0]:g} ms | at {TABLE_BUDGETS[1]:g} ms | for error {TABLE_TARGET:g} |", "|---|---|---|---|---|"]
    for f in frames:
        cells = []
        for kind, v in (("table_budget", TABLE_BUDGETS[0]), ("table_budget", TABLE_BUDGETS[1]), ("table_target", TABLE_TARGET)):
            c = next(c for c in cs if c["scene"] == f["scene"] and c["light"] == f["light"] and c["kind"] == kind and c["value"] == v)
            cells.append(f"{c['setting']}: {c['ms']:.0f} ms, {c['error']:.4f}" + (" (warned)" if c["warned"] else ""))
        L.append(f"| {f['scene']} | {f['light'].split('/')[-1]}{'' if f['metric'] == 'mae_penumbra' else ' (all pixels)'} | " + " | ".join(cells) + " |")
    L += ["", "Cells: the chosen setting, its measured frame time and error. `(warned)`: no candidate was predicted to fit "
          "(the cheapest, or the most accurate, was chosen with a warning).", ""]
    met = lambda ok: "**met**" if ok else "**not met**"  # noqa: E731
    L += ["## Targets", "", "| target | measured | |", "|---|---|---|",
          f"| within the budget (measured ≤ budget × {BUDGET_SLACK:g}) in ≥ {GOALS['within_budget']:.0%} of cases | "
          f"{s['within_budget']:.1%} of {s['budget_cases']} | {met(s['within_budget'] >= GOALS['within_budget'])} |",
          f"| median error regret ≤ {GOALS['error_regret']:g} | {s['error_regret_median']:.4f} (90th percentile {s['error_regret_p90']:.4f}) | "
          f"{met(s['error_regret_median'] <= GOALS['error_regret'])} |",
          f"| median time regret ≤ {GOALS['time_regret']:.0%} | {s['time_regret_median']:.1%} (90th percentile {s['time_regret_p90']:.1%}; "
          f"{s['target_reachable']} of {s['target_cases']} target cases some setting reaches) | {met(s['time_regret_median'] <= GOALS['time_regret'])} |",
          "", f"Budgets: the frame's fastest measured setting × {', × '.join(f'{x:g}' for x in BUDGET_FACTORS)}; error regret: the choice's "
          "measured error minus the lowest measured error within the budget. Targets: error "
          f"{', '.join(f'{e:g}' for e in TARGETS)}; time regret: the choice's measured time over the fastest setting measured to reach "
          f"the target, minus 1 (cases no setting reaches are left out). The target was missed (measured error above it) in "
          f"{s['target_missed']} of {s['target_reachable']} reachable cases; {s['budget_warned']} budget and {s['target_warned']} target "
          "cases warned that no candidate was predicted to serve them.", ""]
    L += flip_flicker_lines(chosen, method, frames, temporal_frames(temporal_rows or [], feature_rows))
    L += ["## Predictors compared (leave-one-scene-out)", "",
          "| time by | error and ꟻLIP by | time: median abs log ratio | predicted time within ×1.5 | error: median abs log ratio | "
          "ꟻLIP: median abs log ratio | within budget | median error regret | median time regret |",
          "|---|---|---|---|---|---|---|---|---|"]
    for (mt, me), r in results.items():
        p, ss = r["prediction"], r["summary"]
        L.append(f"| {mt} | {me} | {p['time_log']:.3f} (×{math.exp(p['time_log']):.2f}) | {p['time_within_1.5']:.0%} | "
                 f"{p['error_log']:.3f} (×{math.exp(p['error_log']):.2f}) | {p['flip_log']:.3f} (×{math.exp(p['flip_log']):.2f}) | "
                 f"{ss['within_budget']:.1%} | {ss['error_regret_median']:.4f} | {ss['time_regret_median']:.1%} |")
    L += ["", f"Over every (setting, held-out frame) pair ({chosen['prediction']['n']}); log-linear: per setting, ridge ({'λ'} = 1) on "
          "standardised features; nearest: mean of the 3 nearest training frames in feature space. The choices use the margin below "
          f"({MARGIN:g}).", ""]
    L += ["## The margin: budget kept against error given up", "",
          "The chooser compares a budget with each setting's time *bound*, its predicted time × exp(margin × the spread of its "
          "log-time residuals in the fit), and a target with the same bound of its error. A larger margin keeps more frames within "
          "the budget and gives up accuracy; the model ships with margin "
          f"{MARGIN:g}. Same held-out predictions as above (time by {method['time']}, error by {method['error']}):", "",
          "| margin | within budget | median error regret | median time regret | targets missed | with the frame's time scale known: within budget | "
          "median error regret |", "|---|---|---|---|---|---|---|"]
    both, best = [], None
    known = scale_known(chosen["held"])
    for z in MARGINS:
        ss, so = summary(cases(chosen["held"], z)), summary(cases(known, z))
        L.append(f"| {z:g} | {ss['within_budget']:.1%} | {ss['error_regret_median']:.4f} | {ss['time_regret_median']:.1%} | "
                 f"{ss['target_missed']} of {ss['target_reachable']} | {so['within_budget']:.1%} | {so['error_regret_median']:.4f} |")
        if ss["within_budget"] >= GOALS["within_budget"] and ss["error_regret_median"] <= GOALS["error_regret"]:
            both.append(z)
        if ss["within_budget"] >= GOALS["within_budget"] and (best is None or ss["error_regret_median"] < best[1]):
            best = (z, ss["error_regret_median"])
    L += ["", (f"Margins meeting both the budget and the error-regret targets: {', '.join(f'{z:g}' for z in both)}." if both else
               f"No margin of these meets both the budget target and the error-regret target on these {len(frames)} frames: held-out "
               f"time predictions are within ×{math.exp(chosen['prediction']['time_log']):.2f} of the measured at the median, and a "
               "setting whose bound is to fit a budget 1.2 or 2 times the fastest setting's time must be one of the few fastest, "
               "mostly the inaccurate ones."
               + (f" The best measured bound keeping ≥ {GOALS['within_budget']:.0%} within the budget: median error regret "
                  f"{best[1]:.4f} (margin {best[0]:g})." if best else "")
               + " The last two columns rescale each held-out frame's predicted times by the median ratio of its measured to "
               "predicted times (known only after rendering every setting): they bound what a better model of a scene's overall "
               "cost could give; what remains is the error in the settings' times relative to one another."), ""]
    L += ["Time models tried, held out the same way (the error as shipped; within budget and median error regret at two margins):", "",
          "| time model | time: median abs log ratio | margin 0.5 | margin 1 |", "|---|---|---|---|"]
    every = ("log_tris", "covered", "log_pen", "shadowed", "log_depth", "cutout", "point")
    tried = [(f"shipped: per setting, {method['time']}" + (f" on {', '.join(X_OF['time'])}" if method["time"] == "loglinear" else ""),
              [dict(h, pq={k: {"time": v["time"], "error": v["error"]} for k, v in h["pq"].items()}) for h in chosen["held"]])]
    tried += [(f"per technique (an intercept per setting, shared slopes) on {', '.join(X_OF['time'])}", pooled_held_out(frames, X_OF["time"])),
              (f"per technique (an intercept per setting, shared slopes) on {', '.join(every)}", pooled_held_out(frames, every))]
    meets = []
    for name, h in tried:
        cells = []
        for z in (0.5, 1.0):
            ss = summary(cases(h, z))
            cells.append(f"{ss['within_budget']:.1%}, {ss['error_regret_median']:.4f}")
            if ss["within_budget"] >= GOALS["within_budget"] and ss["error_regret_median"] <= GOALS["error_regret"]:
                meets.append(f"{name} (margin {z:g})")
        tl = prediction_error(h)["time_log"]
        L.append(f"| {name} | {tl:.3f} (×{math.exp(tl):.2f}) | {cells[0]} | {cells[1]} |")
    L += ["", ("Meeting both the budget and the error-regret targets: " + "; ".join(meets) + "." if meets else
               f"None of these meets both the budget and the error-regret targets on these {len(frames)} frames."), ""]
    L += ["Per goal (margin as shipped):", "", "| goal | cases | within budget / target reached | median error regret | median time regret |",
          "|---|---|---|---|---|"]
    for goal in dict.fromkeys(c["goal"] for c in cs if c["kind"] in ("budget", "target")):
        g = [c for c in cs if c["goal"] == goal and c["kind"] in ("budget", "target")]
        if g[0]["kind"] == "budget":
            L.append(f"| budget: {goal} | {len(g)} | {sum(c['within'] for c in g)} | {_median([c['error_regret'] for c in g]):.4f} | - |")
        else:
            tr = [c["time_regret"] for c in g if c["time_regret"] is not None]
            L.append(f"| target: {goal} | {len(g)} | {sum(c['reached'] for c in g)} | - | {_median(tr):.1%} |")
    L.append("")
    L += ["## The features of each frame", "", "Computed before any technique renders (`wsoft.auto.features.light_features`: a "
          "96-sample-wide G-buffer and a 256² soft depth map of the light); the rows of this sweep.", "",
          "| scene | light | triangles in the light's view | covered pixels | cutout triangles | light size | light distance | shadowed | "
          "penumbra px | receivers' depth ratio | ms to compute |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    ms = {(r["scene"], r["light"]): r.get("features_ms") for r in feature_rows}
    for f in frames:
        x = f["features"]
        L.append(f"| {f['scene']} | {f['light'].split('/')[-1]} | {x['triangles_in_view']:.0f} | {x['covered_pixels']:.0f} | "
                 f"{x['cutout_triangles']:.0f} | {x['light_size']:.3g} | {x['light_distance']:.3g} | {x['shadowed_fraction']:.3f} | "
                 f"{x['penumbra_px']:.3g} | {x['depth_ratio']:.3g} | {ms.get((f['scene'], f['light'])) or '-'} |")
    L += ["", "The feature times include the first upload of the scene (its BVH), which a render then reuses. The rows of "
          "`temporal.jsonl` (sequences, 256x192) feed the flicker model only (above); of `modern.jsonl`'s (modern techniques measured "
          "again on some pareto frames) only entries a pareto row lacks join that row (the count is at the end of this report).", ""]
    L += ["## Every choice (held out)", "", "| scene | light | goal | choice | predicted ms | measured ms | predicted error | measured error | best fixed | its ms | its error | regret |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cs:
        if c["kind"] not in ("budget", "target"):
            continue
        reg = f"{c['error_regret']:+.4f}" if c["kind"] == "budget" else ("-" if c["time_regret"] is None else f"{c['time_regret']:+.0%}")
        flag = "" if (c["within"] if c["kind"] == "budget" else (c["reached"] or c["best"] is None)) else " ✗"
        L.append(f"| {c['scene']} | {c['light'].split('/')[-1]} | {c['goal']} ({c['value']:.4g}) | {c['setting']}{flag} | {c['pred_ms']:.0f} | {c['ms']:.0f} | "
                 f"{c['pred_error']:.4f} | {c['error']:.4f} | {c['best'] or '-'} | " + ("-" if c["best_ms"] is None else f"{c['best_ms']:.0f}") + " | "
                 + ("-" if c["best_error"] is None else f"{c['best_error']:.4f}") + f" | {reg} |")
    L += ["", "✗: over the budget × 1.1, or above the target, measured."]
    return L
