"""The explorable page of a sweep's rows (:mod:`wsoft.bench.html_report`) as one HTML text.

Per scene and light (a group of :mod:`wsoft.bench.html_rows`) a Bokeh plot of error against frame
time on log axes: each technique a scatter in its colour and marker of :mod:`wsoft.palette`, with its
Pareto front dashed (the reference's curve solid); hover tells the technique, the setting, the frame
ms, the error, ꟻLIP and flicker; a click shows beside the plot the point's frame, its difference
from the reference and its ꟻLIP map, or says which of them the sweep did not store. Clicking a
legend entry hides that technique in its plot; the checkboxes at the top hide it in every plot. The
'Which technique to use' table (:func:`wsoft.bench.html_rows.choice`) links each cell to its point.
BokehJS is inlined (its core alone: no widgets, tables or MathJax), so the page works offline; the
images are the PNGs the sweep wrote beside the rows, linked relative to the page.

The page's script exposes ``window.wsoftPoints()`` (the data points the plots hold, counted from
the Bokeh documents' sources), ``window.wsoftSelect(group, point)`` (select a point, as a click
does) and ``window.wsoftSelected`` (the point shown).
"""

from __future__ import annotations

import html
import json
import math

from wsoft.bench.html_rows import SLOTS, choice, has_pairs, table_rows

CSS = """
body{font-family:system-ui,sans-serif;margin:1em 2em;color:#222}
h1{font-size:1.4em} h2{font-size:1.2em;margin-top:1.6em} h3{font-size:1.05em;margin:1.2em 0 .3em}
table{border-collapse:collapse;font-size:.85em;margin:.4em 0} td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}
th{background:#f2f2f2} .grow{display:flex;gap:1em;align-items:flex-start;flex-wrap:wrap}
.detail{flex:1;min-width:420px;font-size:.9em} .imgs{display:flex;gap:.6em;flex-wrap:wrap}
figure{margin:0;max-width:100%} figure img{max-width:100%;border:1px solid #ccc} figcaption{font-size:.8em;color:#555}
figure.none{border:1px dashed #bbb;padding:.6em;width:200px;color:#777;font-size:.85em}
.toggles label{margin-right:1em;white-space:nowrap} .swatch{display:inline-block;width:.8em;height:.8em;margin-right:.2em}
a.pt{cursor:pointer} .note{color:#555;font-size:.9em} .hint{color:#777}
"""

SCRIPT = """
(function(){
const D = window.wsoftData;
const esc = s => String(s).replace(/[&<>"']/g, c => ({'&':'&amp;','<':'&lt;','>':'&gt;','"':'&quot;',"'":'&#39;'}[c]));
const fmt = (x, d) => x === null || x === undefined ? '-' : (Math.abs(x) >= 100 ? x.toFixed(0) : x.toPrecision(d || 4));
function models(){ const out = []; for (const doc of (window.Bokeh ? Bokeh.documents : [])) for (const m of doc.all_models) out.push(m); return out; }
function named(name){ return models().find(m => m.name === name); }
window.wsoftPoints = function(){
  let n = 0; for (const m of models()) if (m.name && m.name.startsWith('src:') && m.data && m.data.x) n += m.data.x.length; return n; };
window.wsoftShow = function(gid, k){
  const g = D.groups.find(g => g.id === gid); const p = g.points[k]; const el = document.getElementById('detail-' + gid);
  if (!g || !p || !el) return;
  let h = '<h4>' + esc(p.setting) + '</h4><table><tr><th>technique</th><td>' + esc(p.technique) + '</td></tr>'
    + '<tr><th>frame ms</th><td>' + fmt(p.ms) + '</td></tr><tr><th>' + esc(g.metric_text) + '</th><td>' + fmt(p.err) + '</td></tr>'
    + '<tr><th>ꟻLIP</th><td>' + fmt(p.flip) + '</td></tr><tr><th>flicker</th><td>' + fmt(p.flicker) + '</td></tr></table><div class="imgs">';
  const have = {}; for (const im of p.images) have[im.slot] = im;
  const fig = im => '<figure><img src="' + esc(im.src) + '" alt="' + esc(im.caption) + '"><figcaption>' + esc(im.caption) + '</figcaption></figure>';
  if (have.side_by_side) h += fig(have.side_by_side);
  for (const [slot, caption] of D.slots) {
    if (have[slot]) { h += fig(have[slot]); continue; }
    if (have.side_by_side && slot !== 'flip') continue;
    h += '<figure class="none" data-slot="' + slot + '">No image: ' + esc(caption) + ' &mdash; '
      + esc((p.missing && p.missing[slot]) || 'the sweep stores none for this setting') + '.</figure>';
  }
  el.innerHTML = h + '</div>'; el.dataset.point = k;
  window.wsoftSelected = {group: gid, point: k, setting: p.setting};
};
window.wsoftSelect = function(gid, k){
  const g = D.groups.find(g => g.id === gid); const p = g && g.points[k];
  if (!p || p.src === null) { if (p) window.wsoftShow(gid, k); return; }
  for (const name of g.sources) { const s = named(name); if (s && name !== p.src) s.selected.indices = []; }
  const s = named(p.src); if (s) s.selected.indices = [p.idx];
  window.wsoftShow(gid, k);
  document.getElementById(gid).scrollIntoView({behavior: 'instant', block: 'start'});
};
window.wsoftFamily = function(tech, on){
  for (const m of models()) if (m.name && m.name.split(':')[2] === tech && 'visible' in m) m.visible = on; };
})();
"""


def _e(x) -> str:
    return html.escape(str(x))


def _num(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x:.0f}" if abs(x) >= 100 else f"{x:.4g}"


def _style(tech: str) -> tuple[str, str]:
    """The technique's colour (hex) and Bokeh marker, after :func:`wsoft.palette.style`."""
    from matplotlib.colors import to_hex

    from wsoft.palette import style

    st = style(tech)
    markers = {"o": "circle", "s": "square", "D": "diamond", "^": "triangle", "v": "inverted_triangle", "P": "plus", "*": "star",
               "X": "x", "h": "hex", "<": "triangle_pin", ">": "square_pin", "p": "star_dot", ".": "circle"}
    return to_hex(st["color"]), markers.get(st["marker"], "circle")


def _techs(group: dict) -> list[str]:
    return sorted({p["technique"] for p in group["points"]}, key=lambda t: (t == "reference", t))


def figure(group: dict, targets: tuple[float, ...]):
    """The group's Bokeh plot; sets each point's ``src`` and ``idx`` (its source and row there) and
    the group's ``sources``."""
    from bokeh.models import ColumnDataSource, CustomJS, HoverTool, Span, TapTool
    from bokeh.plotting import figure as new_figure
    from wsoft.bench.pareto import pareto_front

    gid = group["id"]
    p = new_figure(x_axis_type="log", y_axis_type="log", width=680, height=440, tools="pan,wheel_zoom,box_zoom,reset,save",
                   name=f"fig:{gid}", x_axis_label="frame time (ms)", y_axis_label=group["metric_text"])
    scatters = []
    group["sources"] = []
    for pt in group["points"]:
        pt["src"], pt["idx"] = None, None
    for tech in _techs(group):
        mine = [(k, q) for k, q in enumerate(group["points"]) if q["technique"] == tech and q["ms"] is not None and q["err"] is not None]
        if not mine:
            continue
        color, marker = _style(tech)
        name = f"src:{gid}:{tech}"
        data = {"x": [max(q["ms"], 1e-3) for _, q in mine], "y": [max(q["err"], 1e-5) for _, q in mine], "point": [k for k, _ in mine],
                "technique": [tech] * len(mine), "setting": [q["setting"] for _, q in mine], "ms": [_num(q["ms"]) for _, q in mine],
                "err": [_num(q["err"]) for _, q in mine], "flip": [_num(q["flip"]) for _, q in mine], "flicker": [_num(q["flicker"]) for _, q in mine]}
        src = ColumnDataSource(data, name=name)
        for i, (k, q) in enumerate(mine):
            q["src"], q["idx"] = name, i
        group["sources"].append(name)
        xy = [(max(q["ms"], 1e-3), max(q["err"], 1e-5), k) for k, q in mine]
        pts = sorted(xy) if tech == "reference" else pareto_front(xy)
        if len(pts) > 1:
            p.line([x for x, _, _ in pts], [y for _, y, _ in pts], color=color, line_width=1.5, line_dash="solid" if tech == "reference" else "dashed",
                   legend_label=tech, name=f"line:{gid}:{tech}")
        r = p.scatter("x", "y", source=src, marker=marker, size=9, fill_color=color, line_color=color, fill_alpha=0.6, legend_label=tech,
                      name=f"pts:{gid}:{tech}", selection_fill_alpha=1.0, selection_line_color="red", selection_line_width=3,
                      nonselection_fill_alpha=0.6, nonselection_line_alpha=1.0)
        scatters.append(r)
        src.selected.js_on_change("indices", CustomJS(args={"src": src}, code=(
            f"if (cb_obj.indices.length) {{ const k = src.data.point[cb_obj.indices[0]]; "
            f"if (!window.wsoftSelected || window.wsoftSelected.group !== '{gid}' || window.wsoftSelected.point !== k) "
            f"window.wsoftSelect('{gid}', k); }}")))
    for t in targets:
        p.add_layout(Span(location=t, dimension="width", line_color="grey", line_dash="dotted", line_width=1))
    p.add_tools(HoverTool(renderers=scatters, tooltips=[("technique", "@technique"), ("setting", "@setting"), ("frame ms", "@ms"),
                                                        (group["metric_text"], "@err"), ("ꟻLIP", "@flip"), ("flicker", "@flicker")]))
    p.add_tools(TapTool(renderers=scatters))
    p.legend.click_policy = "hide"
    p.legend.label_text_font_size = "8pt"
    p.legend.spacing = 0
    p.legend.padding = 4
    p.add_layout(p.legend[0], "right")
    return p


def points_table(group: dict) -> str:
    rows = "".join(f"<tr><td>{_e(q['technique'])}</td><td>{_e(q['setting'])}</td><td>{_num(q['ms'])}</td><td>{_num(q['err'])}</td>"
                   f"<td>{_num(q['flip'])}</td><td>{_num(q['flicker'])}</td></tr>" for q in group["points"])
    return (f"<table><tr><th>technique</th><th>setting</th><th>frame ms</th><th>{_e(group['metric_text'])}</th><th>ꟻLIP</th><th>flicker</th></tr>"
            f"{rows}</table>")


def choice_table(groups: list[dict], targets: tuple[float, ...]) -> str:
    """pareto's 'Which technique to use' over the groups with a plot, each cell linked to its point."""
    plotted = [g for g in groups if has_pairs(g)]
    if not plotted:
        return ""
    head = "".join(f"<th>fastest to ≤ {t}</th>" for t in targets) + f"<th>fastest but the reference to ≤ {targets[0]}</th>"
    wins: dict[float, dict[str, int]] = {t: {} for t in targets}
    body = []
    for g in plotted:
        cells = []
        for j, c in enumerate(choice(g, targets)):
            if c is None:
                cells.append("<td>-</td>")
                continue
            if j < len(targets):
                wins[targets[j]][c["technique"]] = wins[targets[j]].get(c["technique"], 0) + 1
            cells.append(f"<td><a class=\"pt\" href=\"#{g['id']}\" data-group=\"{g['id']}\" data-point=\"{c['index']}\" "
                         f"onclick=\"wsoftSelect('{g['id']}', {c['index']}); return false;\">{_e(c['setting'])}, {_num(c['ms'])} ms</a></td>")
        light = g["light"] + ("" if g["metric"] != "mae" else " (all pixels)")
        body.append(f"<tr><td>{_e(g['scene'])}</td><td>{_e(light)}</td>{''.join(cells)}</tr>")
    tally = "".join(f"<li>Fastest to ≤ {t} on {sum(wins[t].values())} of {len(plotted)} frames: "
                    + (", ".join(f"<code>{_e(k)}</code> {n}" for k, n in sorted(wins[t].items(), key=lambda kv: (-kv[1], kv[0]))) or "none")
                    + "</li>" for t in targets)
    return ("<h2 id=\"which\">Which technique to use</h2><p class=\"note\">Per scene and light, the fastest setting of all (the reference "
            "included) whose error is at most each target, and the fastest that is not the reference (<code>-</code>: none does). "
            "Click a cell: its point is selected in its plot.</p>"
            f"<table><tr><th>scene</th><th>light</th>{head}</tr>{''.join(body)}</table><ul>{tally}</ul>")


def _toggles(groups: list[dict]) -> str:
    techs = sorted({p["technique"] for g in groups if has_pairs(g) for p in g["points"]}, key=lambda t: (t == "reference", t))
    if not techs:
        return ""
    boxes = "".join(f"<label><input type=\"checkbox\" checked data-family=\"{_e(t)}\" onchange=\"wsoftFamily(this.dataset.family, this.checked)\">"
                    f"<span class=\"swatch\" style=\"background:{_style(t)[0]}\"></span>{_e(t)}</label>" for t in techs)
    return f"<p class=\"toggles\"><b>Technique families</b> (every plot; a legend entry hides one plot's): {boxes}</p>"


def _row_images(group: dict) -> str:
    if not group["row_images"]:
        return ""
    figs = "".join(f"<figure><img loading=\"lazy\" src=\"{_e(i['src'])}\" alt=\"{_e(i['caption'])}\"><figcaption>{_e(i['caption'])}</figcaption></figure>"
                   for i in group["row_images"])
    return f"<details><summary>Images of this scene and light ({len(group['row_images'])})</summary><div class=\"imgs\">{figs}</div></details>"


def page(sweep: str, groups: list[dict], rows: list[dict], *, baseline_href: str | None = None, note: str = "") -> str:
    """The page's HTML. Groups with time and error pairs get a plot (when Bokeh imports; else, and
    for the others, a table of their points); a sweep without groups, a table of its rows."""
    from wsoft.bench.pareto import TARGETS

    try:
        from bokeh.embed import components
        from bokeh.resources import Resources
    except ImportError:
        from wsoft.bench.common import install_command

        components = None
        note += f" Bokeh is not installed: tables only (for the plots: {install_command('dist')})."
    plots = {g["id"]: figure(g, TARGETS) for g in groups if has_pairs(g)} if components else {}
    script, divs = components(plots) if plots else ("", {})
    js = Resources(mode="inline", components=["bokeh"]).render_js() if plots else ""
    parts = [f"<h1>Sweep <code>{_e(sweep)}</code></h1>",
             (f"<p class=\"note\">{len(rows)} rows in <code>{_e(sweep)}.jsonl</code>; {len(groups)} scenes and lights, "
             f"{sum(len(g['points']) for g in groups)} settings ({sum(g['plotted'] for g in groups)} with a time and an error). "
             f"Images: the PNGs the sweep wrote beside the rows, where it wrote any.{_e(note)}</p>")]
    if baseline_href:
        parts.append(f"<p><a href=\"{_e(baseline_href)}\">Against the baseline</a>: old and new per setting (ratio of times, change of errors).</p>")
    if plots:
        parts.append(_toggles(groups))
        parts.append(choice_table(groups, TARGETS))
    if groups:
        parts.append("<h2>Per scene and light</h2>")
    for g in groups:
        parts.append(f"<section class=\"group\" id=\"{g['id']}\"><h3>{_e(g['title'])}</h3>")
        if g["id"] in divs:
            parts.append(f"<div class=\"grow\"><div class=\"plot\">{divs[g['id']]}</div><div class=\"detail\" id=\"detail-{g['id']}\">"
                         "<p class=\"hint\">Hover a point for its numbers; click it for its frame, its difference from the reference and its "
                         "ꟻLIP map. Dotted: the targets " + ", ".join(map(str, TARGETS)) + ".</p></div></div>")
        else:
            parts.append(points_table(g))
        parts.append(_row_images(g) + "</section>")
    if not groups:
        cols, cells = table_rows(rows)
        parts.append("<h2>Rows</h2><p class=\"note\">The sweep's rows hold no time and error per setting: its rows as a table.</p>"
                     "<table><tr>" + "".join(f"<th>{_e(c)}</th>" for c in cols) + "</tr>"
                     + "".join("<tr>" + "".join(f"<td>{_e(v)}</td>" for v in r) + "</tr>" for r in cells) + "</table>")
    data = {"slots": [list(s) for s in SLOTS], "groups": [
        {"id": g["id"], "title": g["title"], "metric_text": g["metric_text"], "sources": g.get("sources", []),
         "points": [{k: q.get(k) for k in ("technique", "setting", "ms", "err", "flip", "flicker", "images", "missing", "src", "idx")}
                    for q in g["points"]]} for g in groups]}
    blob = json.dumps(data, separators=(",", ":"), default=_jsonable).replace("</", "<\\/")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>wsoft sweep " + _e(sweep) + "</title>"
            f"<style>{CSS}</style>{js}</head><body>{''.join(parts)}"
            f"<script>window.wsoftData = {blob};</script><script>{SCRIPT}</script>{script}</body></html>\n")


def _jsonable(x):
    return None if isinstance(x, float) and not math.isfinite(x) else str(x)
