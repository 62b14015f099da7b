"""What sweeps share: a measured render row with its error from the metric pass, side-by-side
images, the accuracy table and the error-versus-time plot of a report, and readers of the
stats' namespaced counters and pass kinds (reports never parse pass names)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from wsoft.bench.harness import ground_truth, measure_render, reference


def install_command(extra: str) -> str:
    """The command that installs wsoft's optional dependencies ``extra`` the way this wsoft is
    installed: ``pip install -e '.[extra]'`` in the source folder of an editable install (or of a
    source tree that is not installed), else ``pip install 'wsoft[extra]'``."""
    import json
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        text = distribution("wsoft").read_text("direct_url.json")
    except PackageNotFoundError:
        return f"pip install -e '.[{extra}]' in the wsoft source folder"
    editable = bool(text) and bool(json.loads(text).get("dir_info", {}).get("editable"))
    return f"pip install -e '.[{extra}]' in the wsoft source folder" if editable else f"pip install 'wsoft[{extra}]'"


def render_references(case: dict) -> list[dict]:
    """The reference :func:`render_row` measures ``case`` against, as :func:`~wsoft.bench.harness.reference`'s
    arguments (a sweep module's ``references``: error-only jobs a distributed sweep runs apart)."""
    if case.get("kind") != "render" or "ref_samples" not in case:
        return []
    return [{"name": case["scene"], "width": case["width"], "height": case["height"], "light": case["light"], "samples": case["ref_samples"],
             "device": case["device"], "casters": case.get("ref_casters", "all")}]


def render_row(case: dict, ctx: dict, extra=None) -> dict:
    """Render ``case`` (median of 3 after a warm-up) with its error against the cached reference,
    measured by the graph's metric pass. ``extra(frame, reference) -> dict`` adds a sweep's own
    measurements to the row."""
    ref = reference(case["scene"], width=case["width"], height=case["height"], light=case["light"], samples=case["ref_samples"], device=case["device"],
                    casters=case.get("ref_casters", "all"))
    truth = ground_truth(case["scene"], ref, case["light"])
    fr = measure_render(case["scene"], case["technique"], case["params"], device=case["device"], width=case["width"], height=case["height"],
                        light=case["light"], truth=truth)
    st = fr.stats
    row = {
        "scene": case["scene"], "technique": st["technique"], "label": st["label"], "params": st["params"], "device": st["device"],
        "width": case["width"], "height": case["height"], "light": st["light"], "light_label": st["light_labels"][0], "ref_samples": case["ref_samples"],
        "timings_ms": st["timings_ms"], "timings_ms_runs": st["timings_ms_runs"], "timings_by_kind_ms": st["timings_by_kind_ms"],
        "pass_kinds": st["pass_kinds"], "pass_stages": st["pass_stages"], "cpu_ms": st["cpu_ms"],
        "memory_bytes": st["memory_bytes"], "counters": st["counters"], "passes": st["passes"], "error": st["error"],
        "reference_ms": float(ref["ms"]), "ref_casters": case.get("ref_casters", "all"), "warnings": st["warnings"],
    }
    if extra is not None:
        row.update(extra(fr, ref))
    if case.get("image"):
        row["image"] = side_by_side(case, params_label(case["technique"], case["params"]), fr.V, ref["V"], ref["A"], ctx)
    return row


# -- reading rows ---------------------------------------------------------------------------------


def counters(row: dict) -> dict:
    """The technique's counters for the row's light."""
    t = next(iter(row["counters"]["techniques"].values()), {})
    return t.get(row["light_label"], {})


def kind_ms(row: dict, *kinds: str) -> float:
    """Milliseconds the row's frame spent in passes of these kinds."""
    return float(sum(row["timings_by_kind_ms"].get(k, 0.0) for k in kinds))


def stage_ms(row: dict, *stages: str) -> float:
    """Milliseconds the row's frame spent in the technique's passes of these stages."""
    return float(sum(ms for name, ms in row["timings_ms"].items() if row["pass_stages"].get(name) in stages))


def shadow_ms(row: dict) -> float:
    """The light maps and the technique's own passes (the reference's traced rays for it)."""
    return kind_ms(row, "light_map", "technique", "reference")


def params_text(p: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in p.items())


def params_label(technique: str, params: dict) -> str:
    """A technique and its parameters for a picture's label, ``hard: shadow_map_size=1024, bias=0.002``."""
    return f"{technique}: {params_text(params)}" if params else technique


# -- images ----------------------------------------------------------------------------------------


LABEL_PX = 12  # the labels' font size in pixels


def wrap_label(draw, text: str, font, width: int) -> list[str]:
    """``text`` in lines no wider than ``width`` pixels, broken at spaces (a word wider than that, within it)."""
    lines: list[str] = []
    for word in text.split(" "):
        if lines and draw.textlength(f"{lines[-1]} {word}", font=font) <= width:
            lines[-1] += f" {word}"
            continue
        lines.append("")
        for ch in word:
            if lines[-1] and draw.textlength(lines[-1] + ch, font=font) > width:
                lines.append("")
            lines[-1] += ch
    return lines


def side_by_side(case: dict, label: str, v: np.ndarray, ref: np.ndarray, cov: np.ndarray, ctx: dict) -> str:
    """A PNG of the technique's V, the reference's V and 4x their absolute difference, each under
    its label (wrapped to its panel's width); returns its path under the report."""
    from PIL import Image, ImageDraw, ImageFont

    from wsoft.io import to_srgb8

    diff = np.clip(np.abs(v - ref) * 4.0, 0, 1)
    panels = [to_srgb8(v * (cov > 0) + (cov == 0) * 0.15), to_srgb8(ref * (cov > 0) + (cov == 0) * 0.15), (diff * 255).astype(np.uint8)]
    h, w = v.shape
    font = ImageFont.load_default(size=LABEL_PX)
    ref_label = f"reference {case['ref_samples']} spp" + (" (dynamic casters)" if case.get("ref_casters", "all") != "all" else "")
    measure = ImageDraw.Draw(Image.new("L", (1, 1)))
    texts = [wrap_label(measure, t, font, w - 8) for t in (label, ref_label, "|difference| x4")]
    line_h = LABEL_PX + 3
    top = max(len(t) for t in texts) * line_h + 6
    img = Image.new("L", (3 * w, h + top), 255)
    for i, p in enumerate(panels):
        img.paste(Image.fromarray(p, "L"), (i * w, top))
    d = ImageDraw.Draw(img)
    for i, lines in enumerate(texts):
        for k, line in enumerate(lines):
            d.text((i * w + 4, 3 + k * line_h), line, fill=0, font=font)
    light = (case.get("light") or "light").split("/")[-1]
    name = f"{case['scene']}-{light}-{case['technique']}-{case['device'].replace(':', '')}.png"
    rel = Path("images") / ctx["stem"] / name
    path = ctx["out_dir"] / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)
    return str(rel)


# -- report parts ----------------------------------------------------------------------------------


def report_header(sweep: str, rows: list[dict], md: Path, ctx: dict) -> list[str]:
    """Title, command, machine and what the rows hold (scenes, devices, resolutions, from the rows)."""
    m = rows[0]["machine"] if rows else {}
    L = [f"# Sweep `{sweep}`{' (quick)' if ctx['quick'] else ''}", ""]
    L.append(f"Produced by `{ctx['command']}` (rows: `{md.with_suffix('.jsonl').name}`; rerun resumes, `--fresh` starts over).")
    L.append(f"Machine: {m.get('cpu', '?')}, {m.get('threads', '?')} CPU threads for Warp launches, Python {m.get('python', '?')}.")
    scenes = sorted({r["scene"] for r in rows if "scene" in r})
    devices = sorted({r["device"] for r in rows if "device" in r})
    res = sorted({f"{r['width']}x{r['height']}" for r in rows if "width" in r}, key=lambda t: int(t.split("x")[0]))
    if scenes:
        L.append(f"Rows: {len(rows)} on {', '.join(f'`{s}`' for s in scenes)}; device {', '.join(devices)}; {', '.join(res)} pixels.")
    L.append("Error is against the cached ray-traced reference on the same covered pixels, measured by the frame graph's metric pass;")
    L.append("penumbra = reference in (0.01, 0.99); `>3se` = fraction of pixels further than 3 reference standard errors from it.")
    L.append("Times: median of 3 runs after a warm-up.")
    L += host_lines(rows)
    L.append("")
    return L


def host_lines(rows: list[dict]) -> list[str]:
    """Where the rows ran, per host (rows, Warp's CPU threads, the hosts' load as rows finished), and
    for rows run on Dask workers the warm-up apart: each worker's scene loads with their BVH (once per
    worker and scene) and the kernel compiles and loads during the rows. Nothing for rows from
    one host run in-process."""
    by_host: dict[str, list[dict]] = {}
    for r in rows:
        by_host.setdefault(r.get("machine", {}).get("host", "?"), []).append(r)
    workers = [r for r in rows if r.get("worker")]
    if len(by_host) <= 1 and not workers:
        return []
    L = []
    for host, mine in sorted(by_host.items()):
        loads = [r["machine"]["load"] for r in mine if r.get("machine", {}).get("load") is not None]
        threads = sorted({r["machine"].get("threads") for r in mine if "machine" in r}, key=str)
        L.append(f"Host `{host}`: {len(mine)} rows, {'/'.join(map(str, threads))} CPU threads"
                 + (f", load {min(loads):.1f}-{max(loads):.1f}" if loads else "") + ".")
    if len(by_host) > 1:
        L.append("Times compare only within one host: read each time beside the rows of its own host.")
    if workers:
        loads = {(r["machine"].get("host"), r["worker"]["pid"], r["scene"]): r["worker"]["scene_load_s"] for r in workers if "scene" in r}
        L.append(f"Dask workers: {len({(r['machine'].get('host'), r['worker']['pid']) for r in workers})} processes ran the rows; "
                 f"scene loads and BVH builds {sum(loads.values()):.1f} s ({len(loads)} worker-scene pairs, once each); "
                 f"kernel compiles and loads within the rows {sum(r['worker'].get('compile_s', 0) for r in workers):.1f} s.")
    return L


def accuracy_table(renders: list[dict]) -> list[str]:
    L = ["## Accuracy and time", ""]
    L.append("`frame ms`: the whole render with the scene already on the device (its BVH is built once per scene and device);")
    L.append("`G-buffer ms`: the eye-view pass; `shadow ms`: the light views, depth maps and the technique's own passes.")
    L.append("")
    L.append("| scene | light | device | res | technique | params | frame ms | G-buffer ms | shadow ms | MAE | RMSE | max | MAE penumbra | >3se | reference occluders |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(renders, key=lambda r: (r["scene"], r["light"], r["device"], r["width"], r["technique"], str(r["params"]))):
        p = r["case"]["params"]
        e = r["error"]
        L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['device']} | {r['width']}x{r['height']} | {r['technique']} | "
                 f"{params_text(p)} | {r['timings_ms']['total']:.1f} | {kind_ms(r, 'gbuffer'):.1f} | {shadow_ms(r):.1f} | {e['mae']:.4f} | "
                 f"{e['rmse']:.4f} | {e['max']:.3f} | {e['mae_penumbra']:.4f} | {e.get('frac_outside_3se', 0):.3f} | {r.get('ref_casters', 'all')} |")
    return L


def lowest_mae(renders: list[dict]) -> dict[tuple[str, str], dict]:
    """The row with the lowest MAE of each (scene, technique)."""
    best: dict[tuple[str, str], dict] = {}
    for r in renders:
        key = (r["scene"], r["technique"])
        if key not in best or r["error"]["mae"] < best[key]["error"]["mae"]:
            best[key] = r
    return best


LIGHT_LINES = ("-", "--", ":", "-.")  # the first, second, ... light of a panel


def log_ticks(ax) -> None:
    """Labelled ticks on both log axes of ``ax`` (call it after plotting): the powers of ten where
    at least two lie in view, else about four ticks spread over the view and rounded to two
    significant digits (a range narrower than a decade shows no power of ten)."""
    import matplotlib.ticker

    for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        lo, hi = sorted(lim)
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        if not lo > 0.0 or math.floor(math.log10(hi)) - math.ceil(math.log10(lo)) >= 1:
            continue
        ticks = sorted({float(f"{v:.2g}") for v in np.geomspace(lo, hi, 6)[1:-1]})
        ticks = [t for t in ticks if lo <= t <= hi] or [float(f"{math.sqrt(lo * hi):.3g}")]
        axis.set_major_locator(matplotlib.ticker.FixedLocator(ticks))
        axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))


def error_vs_time(renders: list[dict], md: Path, ctx: dict, title: str) -> list[str]:
    """One panel per scene: MAE against frame time, a line per (light, device, technique) over its
    sweep. Each technique in its colour and marker of the one palette (:mod:`wsoft.palette`; a
    technique's several series, ``row["technique"]`` naming a group of ``row["case"]["technique"]``,
    in its shades), a panel's lights told apart by the line, other devices by open markers; one
    legend for the figure, where no data lies."""
    if not renders:
        return []
    import matplotlib
    import matplotlib.ticker
    from matplotlib.lines import Line2D

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.palette import variant_style

    plot_rel = Path("images") / ctx["stem"] / "error_vs_time.png"
    width = max(x["width"] for x in renders)
    scenes = sorted({r["scene"] for r in renders})
    devices = sorted({r["device"] for r in renders})

    def tech(r: dict) -> str:  # the palette's technique of a row whose "technique" may name a group
        return r.get("case", {}).get("technique", r["technique"])

    series = sorted({(tech(r), r["technique"]) for r in renders}, key=lambda s: (s[0] == "reference", s))
    styles = {}
    for t, label in series:
        k = sum(1 for t2, _ in styles if t2 == t)
        styles[(t, label)] = variant_style(t, k)
    ncols = min(3, len(scenes))
    nrows = (len(scenes) + ncols - 1) // ncols
    spare = ncols * nrows - len(scenes)
    n_handles = len(series) + (len(devices) if len(devices) > 1 else 0)
    legend_cols = min(n_handles, 6)
    legend_in = 0 if spare else 0.3 + 0.2 * math.ceil(n_handles / legend_cols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.6 * nrows + legend_in), squeeze=False)
    for ax, scene in zip(axes.flat, scenes):
        mine = [r for r in renders if r["scene"] == scene and r["width"] == width]
        lights = sorted({r["light"].split("/")[-1] for r in mine})
        for (t, label) in series:
            for light in lights:
                for dev in devices:
                    pts = sorted((r["timings_ms"]["total"], max(r["error"]["mae"], 1e-5)) for r in mine
                                 if (tech(r), r["technique"], r["light"].split("/")[-1], r["device"]) == (t, label, light, dev))
                    if not pts:
                        continue
                    st = styles[(t, label)]
                    ax.plot(*zip(*pts), marker=st["marker"], color=st["color"], markersize=5, linewidth=1.0,
                            linestyle=LIGHT_LINES[lights.index(light) % len(LIGHT_LINES)],
                            markerfacecolor=st["color"] if dev == devices[0] else "none")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(scene + (" (lights: " + ", ".join(f"{l} {LIGHT_LINES[i % len(LIGHT_LINES)]}" for i, l in enumerate(lights)) + ")"
                              if len(lights) > 1 else ""), fontsize=9)
        ax.set_xlabel("frame time (ms)", fontsize=8)
        ax.set_ylabel("MAE of V", fontsize=8)
        ax.tick_params(labelsize=7)
        log_ticks(ax)
    handles = [Line2D([], [], color=styles[s]["color"], marker=styles[s]["marker"], markersize=5, linewidth=1.0, label=s[1]) for s in series]
    handles += [Line2D([], [], color="grey", marker="o", markerfacecolor="none" if i else "grey", linestyle="none", label=f"on {d}")
                for i, d in enumerate(devices) if len(devices) > 1]
    for ax in list(axes.flat)[len(scenes):]:
        ax.axis("off")
    fig.suptitle(f"{title} ({width} px wide)", fontsize=9)
    if spare:  # the legend in the first empty panel
        list(axes.flat)[len(scenes)].legend(handles=handles, loc="center", fontsize=8, ncols=1 + len(handles) // 12, frameon=False)
        fig.tight_layout()
    else:  # below the panels
        fig.legend(handles=handles, loc="lower center", fontsize=8, ncols=legend_cols, frameon=False)
        fig.tight_layout(rect=(0, legend_in / fig.get_figheight(), 1, 1))
    (md.parent / plot_rel).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(md.parent / plot_rel, dpi=110)
    plt.close(fig)
    return ["", "## Error against time", "", f"![error vs time]({plot_rel.as_posix()})"]


def image_list(renders: list[dict], what: str) -> list[str]:
    imgs = [r for r in renders if r.get("image")]
    if not imgs:
        return []
    L = ["", f"## Images ({what})", ""]
    for r in sorted(imgs, key=lambda r: (r["scene"], r["light"], r["technique"])):
        L.append(f"**{r['scene']} / {r['light'].split('/')[-1]} / {r['technique']}** ({r['device']})")
        L.append("")
        L.append(f"![{r['scene']}]({r['image']})")
        L.append("")
    return L
