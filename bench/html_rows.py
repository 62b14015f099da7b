"""The rows of any sweep as the explorable page's groups and points (:mod:`wsoft.bench.html_report`).

A *group* is one scene and light (and device and resolution): a row holding ``entries`` (pareto,
temporal, cube, modern: one frame graph per scene and light) is one group, its entries its points;
rows measured one setting each (foundation, filtered, essm, stsv, izb: ``error`` or ``mae`` beside
``timings_ms``) are grouped by scene, light, device and resolution, each row a point. A point has a
technique, a setting, its frame time, its error (the group's metric: penumbra MAE, or the MAE over
all pixels where the reference has no penumbra, :func:`wsoft.bench.pareto.row_metric`; a temporal
entry's mean over its frames), its ꟻLIP and flicker where measured, and the images the sweep wrote
for it:

* ``entry["images"]``: ``{"frame": PATH, "difference": PATH, "flip": PATH}`` (any of them), each a
  path under the report's folder;
* ``entry["image"]`` (or a single-setting row's ``image``): one PNG of the setting's V, the
  reference's V and their difference side by side (:func:`wsoft.bench.common.side_by_side`).

A group also shows the images the sweep wrote for its scene and light as a whole (the row's
``strip``; ``images/<report>/<scene>-<light>*.png``: the sweep's own plot). What a point lacks, the
page says it lacks.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

SLOTS = (("frame", "the setting's frame (V)"), ("difference", "its difference from the reference"), ("flip", "its ꟻLIP map"))
SIDE_BY_SIDE = "the setting's V, the reference's V and |difference| x4 (one image)"


def _finite(x) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None


def _image(out_dir: Path, path: str | None) -> dict | None:
    """``path`` (relative to the report's folder) as the page links it, whether its file is there."""
    if not path:
        return None
    rel = Path(path)
    return {"src": rel.as_posix(), "exists": (out_dir / rel).is_file()}


def point_images(src: dict, out_dir: Path) -> tuple[list[dict], dict[str, str]]:
    """The images a point has (``slot``, ``src``, ``caption``), and for each slot whose image the
    entry names but the report's folder lacks, a sentence saying so (a slot the entry names no
    image for: the page says the sweep stores none)."""
    images, missing = [], {}
    named = src.get("images") if isinstance(src.get("images"), dict) else {}
    for slot, caption in (("side_by_side", SIDE_BY_SIDE),) + SLOTS:
        img = _image(out_dir, src.get("image") if slot == "side_by_side" else named.get(slot))
        if img and img["exists"]:
            images.append({"slot": slot, "src": img["src"], "caption": caption})
        elif img:
            missing[slot] = f"{img['src']} is not in the report's folder"
    return images, missing


def _light(row: dict) -> tuple[str, str]:
    path = row.get("light") or ""
    return path, path.split("/")[-1] if path else "-"


def _ms(x: dict) -> float | None:
    if "frame_ms" in x:
        return _finite(x["frame_ms"])
    t = x.get("timings_ms")
    return _finite(t.get("total")) if isinstance(t, dict) else _finite(t)


def _errors(x: dict) -> tuple[dict, float | None, float | None, bool]:
    """(error dict, ꟻLIP, flicker, over frames) of an entry or a single-setting row."""
    if isinstance(x.get("temporal"), dict):
        t = x["temporal"]
        err = {k: t[k] for k in ("mae_penumbra", "mae") if _finite(t.get(k)) is not None}
        return err, _finite(x.get("flip")), _finite(t.get("flicker")), True
    if isinstance(x.get("error"), dict):
        e = x["error"]
        return e, _finite(e.get("flip", x.get("flip"))), None, False
    err = {"mae": x["mae"]} if _finite(x.get("mae")) is not None else {}
    return err, _finite(x.get("flip")), None, False


def metric(errors: list[dict], temporal: bool) -> str | None:
    """The error a group ranks by (:func:`wsoft.bench.pareto.row_metric` where every error counts
    penumbra pixels, else penumbra MAE where measured, else MAE); None: no error."""
    from wsoft.bench.pareto import row_metric

    if errors and all("penumbra_pixels" in e for e in errors) and not temporal:
        return row_metric({"entries": [{"error": e} for e in errors]})
    for m in ("mae_penumbra", "mae"):
        if errors and all(_finite(e.get(m)) is not None for e in errors):
            return m
    return None


def metric_text(m: str | None, temporal: bool) -> str:
    from wsoft.bench.pareto import METRIC_TEXT

    text = METRIC_TEXT.get(m, m or "no error")
    return f"{text}, mean over the frames" if temporal and m else text


def setting(x: dict) -> str:
    """The entry's label where it names its parameters, else its technique and parameters."""
    p = (x.get("case") or {}).get("params", x.get("params")) or {}
    if x.get("label") and ("(" in str(x["label"]) or not p):
        return str(x["label"])
    return f"{x.get('technique', '?')}" + (f"({', '.join(f'{k}={v}' for k, v in p.items())})" if p else "")


def _point(x: dict, out_dir: Path) -> dict:
    err, flip, flicker, temporal = _errors(x)
    images, missing = point_images(x, out_dir)
    return {"technique": str(x.get("technique") or x.get("group") or "?"), "setting": setting(x), "ms": _ms(x), "error": err,
            "flip": flip, "flicker": flicker, "temporal": temporal, "images": images, "missing": missing}


def row_images(row: dict, out_dir: Path, stem: str, claimed: set[str]) -> list[dict]:
    """Images of a group's scene and light as a whole: the row's ``strip`` and the sweep's PNGs named
    after the scene and light (not a point's own)."""
    out = []
    strip = _image(out_dir, row.get("strip"))
    if strip and strip["exists"]:
        out.append({"src": strip["src"], "caption": "the row's strip: several settings' frames side by side"})
    _, light = _light(row)
    folder = out_dir / "images" / stem
    if folder.is_dir() and row.get("scene"):
        for f in sorted(folder.glob(f"{row['scene']}-{light}*.png")):
            rel = f.relative_to(out_dir).as_posix()
            if rel not in claimed and all(rel != o["src"] for o in out):
                out.append({"src": rel, "caption": f"the sweep's image {f.name}"})
    return out


def groups(rows: list[dict], out_dir: Path, stem: str) -> list[dict]:
    """The rows as groups of points (see the module docstring), ordered by scene, light, device and
    resolution; rows with neither entries nor a time are left out (:func:`table_rows` shows them)."""
    out_dir = Path(out_dir)
    buckets: dict[tuple, dict] = {}
    for n, r in enumerate(rows):
        if not isinstance(r, dict) or r.get("failed"):
            continue
        path, light = _light(r)
        size = f"{r['width']}x{r['height']}" if "width" in r and "height" in r else ""
        key = (str(r.get("scene", "")), path, str(r.get("device", "")), size)
        if isinstance(r.get("entries"), list):
            buckets[key + (f"{n:06d}",)] = {"row": r, "sources": [e for e in r["entries"] if isinstance(e, dict)]}
        elif _ms(r) is not None and r.get("scene"):
            buckets.setdefault(key, {"row": r, "sources": []})["sources"].append(r)
    out = []
    for key in sorted(buckets, key=lambda k: tuple(map(str, k))):
        b = buckets[key]
        r = b["row"]
        points = [_point(x, out_dir) for x in b["sources"]]
        temporal = any(p["temporal"] for p in points)
        m = metric([p["error"] for p in points], temporal)
        for p in points:
            p["err"] = _finite(p["error"].get(m)) if m else None
        claimed = {i["src"] for p in points for i in p["images"]}
        path, light = _light(r)
        title = f"{r.get('scene', '?')}" + (f" / {light}" if path else "") + (f" ({r['light_kind']})" if r.get("light_kind") else "") + \
            (f", {key[3]}" if key[3] else "") + (f", {key[2]}" if key[2] else "")
        out.append({"id": f"g{len(out)}", "scene": str(r.get("scene", "")), "light": light, "light_path": path, "device": key[2], "size": key[3],
                    "match": list(key[:4]), "title": title, "metric": m, "metric_text": metric_text(m, temporal), "temporal": temporal,
                    "points": points, "row_images": row_images(r, out_dir, stem, claimed),
                    "plotted": sum(1 for p in points if p["ms"] is not None and p["err"] is not None)})
    return out


def has_pairs(group: dict) -> bool:
    """Does the group hold a point with both a time and an error (a plot; else a table only)?"""
    return group["plotted"] > 0


def choice(group: dict, targets: tuple[float, ...] | None = None) -> list[dict | None]:
    """The group's cells of pareto's 'Which technique to use' table
    (:func:`wsoft.bench.pareto.choice_section`): the fastest point reaching each target
    (:func:`wsoft.bench.pareto.time_to_reach`), then the fastest but the reference reaching the first."""
    from wsoft.bench.pareto import TARGETS, time_to_reach

    targets = targets or TARGETS
    m = group["metric"]
    entries = [{"error": {m: p["err"]}, "frame_ms": p["ms"], "technique": p["technique"], "index": i}
               for i, p in enumerate(group["points"]) if p["ms"] is not None and p["err"] is not None]
    cells = [time_to_reach(entries, t, m) for t in targets]
    cells.append(time_to_reach([e for e in entries if e["technique"] != "reference"], targets[0], m))
    return [None if c is None else group["points"][c["index"]] | {"index": c["index"]} for c in cells]


SKIP_COLUMNS = ("key", "case", "machine", "sweep", "worker", "entries")


def cell_text(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (dict, list)):
        s = json.dumps(v, default=str)
        return s if len(s) <= 120 else s[:117] + "..."
    return str(v)


def table_rows(rows: list[dict]) -> tuple[list[str], list[list[str]]]:
    """Any rows as a table: the columns their top-level fields (their bookkeeping left out), each
    value as text (nested values as JSON, cut at 120 characters)."""
    cols: list[str] = []
    for r in rows:
        for k in r:
            if k not in SKIP_COLUMNS and k not in cols:
                cols.append(k)
    return cols, [[cell_text(r[k]) if k in r else "" for k in cols] for r in rows]
