"""A sweep's rows against a baseline's (an earlier run of the same sweep) as an HTML page: per
scene and light (:func:`wsoft.bench.html_rows.groups`, matched by scene, light path, device and
resolution) and setting (matched by technique and setting), the old and new frame time with their
ratio (new / old), and the old and new error, ꟻLIP and flicker with their change (new - old).
Settings in one run alone are listed apart. Plain HTML: no script."""

from __future__ import annotations

import html
import math
from pathlib import Path

from wsoft.bench.html_rows import groups as to_groups


def _e(x) -> str:
    return html.escape(str(x))


def _f(x: float | None, spec: str = ".4g") -> str:
    return "-" if x is None else format(x, spec)


def _delta(new: float | None, old: float | None) -> float | None:
    return None if new is None or old is None else new - old


def _ratio(new: float | None, old: float | None) -> float | None:
    return None if new is None or old is None or old <= 0 else new / old


def compare(rows: list[dict], baseline_rows: list[dict], out_dir: Path, stem: str) -> dict:
    """``{"pairs": [...], "only_new": [...], "only_old": [...]}``: each pair a scene and light's
    setting in both runs with its ratio of times and changes of errors."""
    new, old = to_groups(rows, out_dir, stem), to_groups(baseline_rows, out_dir, stem)
    old_by = {tuple(g["match"]): g for g in old}
    pairs, only_new, only_old = [], [], []
    seen = set()
    for g in new:
        key = tuple(g["match"])
        b = old_by.get(key)
        seen.add(key)
        before = {(q["technique"], q["setting"]): q for q in (b["points"] if b else [])}
        for q in g["points"]:
            o = before.pop((q["technique"], q["setting"]), None)
            if o is None:
                only_new.append((g["title"], q["setting"]))
                continue
            pairs.append({"group": g["title"], "metric": g["metric_text"], "technique": q["technique"], "setting": q["setting"],
                          "old_ms": o["ms"], "new_ms": q["ms"], "ratio": _ratio(q["ms"], o["ms"]), "old_err": o["err"], "new_err": q["err"],
                          "d_err": _delta(q["err"], o["err"]), "d_flip": _delta(q["flip"], o["flip"]), "d_flicker": _delta(q["flicker"], o["flicker"])})
        only_old += [(g["title"], s) for _, s in before]
    only_old += [(g["title"], q["setting"]) for g in old if tuple(g["match"]) not in seen for q in g["points"]]
    return {"pairs": pairs, "only_new": only_new, "only_old": only_old}


def _geomean(xs: list[float]) -> float | None:
    xs = [x for x in xs if x is not None and x > 0]
    return math.exp(sum(map(math.log, xs)) / len(xs)) if xs else None


def page(sweep: str, rows: list[dict], baseline_rows: list[dict], out_dir: Path, stem: str, main_href: str) -> str:
    c = compare(rows, baseline_rows, out_dir, stem)
    techs = sorted({p["technique"] for p in c["pairs"]})
    summary = "".join(
        f"<tr><td>{_e(t)}</td><td>{len(mine)}</td><td>{_f(_geomean([p['ratio'] for p in mine]), '.3f')}</td>"
        f"<td>{_f(_mean([p['d_err'] for p in mine]), '+.4g')}</td></tr>"
        for t in techs for mine in [[p for p in c["pairs"] if p["technique"] == t]])
    body = "".join(
        f"<tr><td>{_e(p['group'])}</td><td>{_e(p['setting'])}</td><td>{_f(p['old_ms'], '.1f')}</td><td>{_f(p['new_ms'], '.1f')}</td>"
        f"<td class=\"{_cls(p['ratio'], 1.0)}\">{_f(p['ratio'], '.3f')}</td><td>{_f(p['old_err'])}</td><td>{_f(p['new_err'])}</td>"
        f"<td class=\"{_cls(p['d_err'], 0.0)}\">{_f(p['d_err'], '+.4g')}</td><td>{_f(p['d_flip'], '+.4g')}</td><td>{_f(p['d_flicker'], '+.4g')}</td></tr>"
        for p in c["pairs"])
    apart = ""
    for what, items in (("Only in the new rows", c["only_new"]), ("Only in the baseline", c["only_old"])):
        if items:
            apart += f"<h2>{what} ({len(items)})</h2><ul>" + "".join(f"<li>{_e(g)}: {_e(s)}</li>" for g, s in items) + "</ul>"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>wsoft sweep " + _e(sweep) + " against its baseline</title>"
            "<style>body{font-family:system-ui,sans-serif;margin:1em 2em}table{border-collapse:collapse;font-size:.85em}"
            "td,th{border:1px solid #ccc;padding:2px 6px}th{background:#f2f2f2}.up{background:#fde0dc}.down{background:#dcf5e0}</style></head><body>"
            f"<h1>Sweep <code>{_e(sweep)}</code> against its baseline</h1><p><a href=\"{_e(main_href)}\">The sweep's page</a>. "
            f"{len(c['pairs'])} settings in both runs ({len(rows)} rows now, {len(baseline_rows)} in the baseline). Ratio: new time / old time "
            "(below 1: faster; red: slower, green: faster); changes: new - old (red: worse, green: better). Times compare only between runs "
            "on the same machine.</p>"
            "<h2>Per technique</h2><table><tr><th>technique</th><th>settings</th><th>geometric mean of the time ratios</th>"
            f"<th>mean change of the error</th></tr>{summary}</table>"
            "<h2>Per setting</h2><table><tr><th>scene / light</th><th>setting</th><th>old ms</th><th>new ms</th><th>ratio</th><th>old error</th>"
            f"<th>new error</th><th>error change</th><th>ꟻLIP change</th><th>flicker change</th></tr>{body}</table>{apart}</body></html>\n")


def _mean(xs: list[float | None]) -> float | None:
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


def _cls(x: float | None, neutral: float) -> str:
    if x is None or abs(x - neutral) < 1e-9:
        return ""
    return "up" if x > neutral else "down"
