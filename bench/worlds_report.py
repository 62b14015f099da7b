"""The report of sweep ``worlds`` (:mod:`wsoft.bench.worlds`): the issue's targets as rows, then per
frame an error-against-time plot and table (time, penumbra MAE, memory, counters) and per sequence
its flicker and page counters frame by frame. Only what the rows hold is stated."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

TECHNIQUES = ("csm", "vsmap", "smrt")  # the large-world techniques the sweep measures, when registered
PRESET_ENV = "WSOFT_WORLDS"            # the variable naming the sweep's preset (full, cpu)
TARGET_MAE = 0.05
PAGE_SHARE = 0.05      # vsmap: pages rendered per frame over a dense 16K² map's texels
REUSE = 0.90           # vsmap: share of requested pages reused from the second frame on
BAND_RATIO = 1.5       # csm: error near the splits over the error away from them
CONTEXT = ("pcss", "pcf")  # the map techniques beside them (one map, no splits: the split band's control)
CONTEXT_MAP = 2048


def registered() -> tuple[list[str], list[str]]:
    """(registered, missing) of :data:`TECHNIQUES` in this process."""
    from wsoft.techniques import TECHNIQUES as REG

    return [t for t in TECHNIQUES if t in REG], [t for t in TECHNIQUES if t not in REG]


def _mib(b) -> str:
    return "-" if b is None else f"{b / 2 ** 20:.1f} MiB"


def memory_text(m: dict) -> str:
    if "cascade_bytes" in m:
        return f"cascades {_mib(m['cascade_bytes'])}"
    if "pool_bytes" in m:
        return f"pool {_mib(m['pool_bytes'])} ({_mib(m['resident_bytes'])} resident)"
    if "map_bytes" in m:
        return f"map {_mib(m['map_bytes'])}"
    return "-"


def counters_text(tech: str, c: dict) -> str:
    if tech == "csm" and "splits" in c:
        return ("splits " + ", ".join(f"{s:.3g}" for s in c["splits"]) + " m; texels " + ", ".join(f"{t:.3g}" for t in c.get("texel_size", []))
                + f" m; {c.get('partition', '?')}, {'stable' if c.get('stable') else 'fitted'}")
    if "rendered" in c:
        return (f"pages requested {c['requested']}, rendered {c['rendered']}, reused {c.get('reused', 0)}, evicted {c.get('evicted', 0)}, "
                f"overflow {c.get('overflow_pages', 0)}")
    return "-"


def dense_share(c: dict) -> float | None:
    """Pages rendered over the pages of one dense virtual map (``dense_pages`` / ``levels``): the
    share of a dense 16K² map's texels drawn this frame."""
    if not c.get("dense_pages") or not c.get("levels"):
        return None
    return c["rendered"] / (c["dense_pages"] / c["levels"])


def _entry(row: dict, label: str) -> dict | None:
    return next((e for e in row["entries"] if e["label"] == label), None)


def _first(row: dict, tech: str) -> dict | None:
    return next((e for e in row["entries"] if e["technique"] == tech and not e["params"]), None)


def _ref16(row: dict) -> dict | None:
    return next((e for e in row["entries"] if e["technique"] == "reference" and e["params"].get("samples") == 16), None)


def _yes(ok: bool | None) -> str:
    return "-" if ok is None else ("yes" if ok else "no")


def target_rows(frames: list[dict], seqs: list[dict], techs: list[str]) -> list[str]:
    L = ["| target | frame | measured | met |", "|---|---|---|---|"]
    for r in frames:
        ref = _ref16(r)
        ok = [e for e in r["entries"] if e["technique"] in techs and e["error"]["mae_penumbra"] <= TARGET_MAE]
        if ref is None:
            continue
        if ok:
            e = min(ok, key=lambda e: e["frame_ms"])
            L.append(f"| fastest of {', '.join(techs) or 'none'} at penumbra MAE ≤ {TARGET_MAE} faster than the reference at 16 spp | {r['scene']} | "
                     f"{e['label']}: {e['frame_ms']:.0f} ms at {e['error']['mae_penumbra']:.4f}; reference 16 spp {ref['frame_ms']:.0f} ms "
                     f"at {ref['error']['mae_penumbra']:.4f} | {_yes(e['frame_ms'] < ref['frame_ms'])} |")
        else:
            best = min((e for e in r["entries"] if e["technique"] in techs), key=lambda e: e["error"]["mae_penumbra"], default=None)
            got = f"none reaches it (best {best['label']}: {best['error']['mae_penumbra']:.4f})" if best else "no technique ran"
            L.append(f"| fastest of {', '.join(techs) or 'none'} at penumbra MAE ≤ {TARGET_MAE} faster than the reference at 16 spp | {r['scene']} | "
                     f"{got}; reference 16 spp {ref['frame_ms']:.0f} ms at {ref['error']['mae_penumbra']:.4f} | no |")
    for r in frames:
        e = _first(r, "vsmap")
        s = dense_share(e["counters"]) if e else None
        if s is not None and r["scene"] == "open_world":
            L.append(f"| vsmap pages rendered ≤ {PAGE_SHARE:.0%} of a dense 16K² map's texels | {r['scene']} (one frame, nothing cached) | "
                     f"{e['counters']['rendered']} pages = {s:.2%} | {_yes(s <= PAGE_SHARE)} |")
    for r in seqs:
        e = _first(r, "vsmap")
        if e is None:
            continue
        cs = e["counters_frames"]
        shares = [dense_share(c) for c in cs]
        if all(s is not None for s in shares):
            L.append(f"| vsmap pages rendered per frame ≤ {PAGE_SHARE:.0%} of a dense 16K² map | {r['scene']} ({len(cs)} frames) | "
                     f"largest {max(shares):.2%} (frame {r['frames'][int(np.argmax(shares))]:g}) | {_yes(max(shares) <= PAGE_SHARE)} |")
        later = [c["reused"] / c["requested"] for c in cs[1:] if c.get("requested")]
        if r["scene"] == "open_world_flyby" and later:
            L.append(f"| vsmap reuses ≥ {REUSE:.0%} of the requested pages from the second frame on (still sun) | {r['scene']} | "
                     f"smallest {min(later):.1%}, mean {np.mean(later):.1%} over frames 2..{len(cs)} | {_yes(min(later) >= REUSE)} |")
    flyby = next((r for r in seqs if r["scene"] == "open_world_flyby"), None)
    sunset = next((r for r in seqs if r["scene"] == "open_world_sunset"), None)
    for tech in ("vsmap", "smrt"):
        a, b = (_first(flyby, tech) if flyby else None), (_first(sunset, tech) if sunset else None)
        if a and b and len(a["counters_frames"]) > 1:
            ra = np.mean([c["rendered"] for c in a["counters_frames"][1:]])
            rb = np.mean([c["rendered"] for c in b["counters_frames"][1:]])
            ta, tb = np.median(a["frame_ms_frames"][1:]), np.median(b["frame_ms_frames"][1:])
            L.append(f"| (cost) the sun turning invalidates {tech}'s pages every frame | open_world_sunset against open_world_flyby, frames 2.. | "
                     f"pages rendered a frame {ra:.0f} → {rb:.0f}; frame time (median) {ta:.0f} → {tb:.0f} ms ({tb / ta:.2f}x) | - |")
    for r in frames:
        e = _first(r, "csm")
        sb = e.get("split_band") if e else None
        if sb:
            ok = None if sb["ratio"] is None else sb["ratio"] <= BAND_RATIO
            got = (f"band MAE {sb['band_mae']:.4f} ({sb['band_pixels']} px) / away {sb['away_mae']:.4f} = {sb['ratio']:.2f}" if sb["ratio"] is not None
                   else f"{sb['band_pixels']} px within {8} px of a split, {sb['away_pixels']} px away: nothing to compare")
            L.append(f"| csm error within {16} px of a split ≤ {BAND_RATIO}x the error away from it | {r['scene']} | {got} | {_yes(ok)} |")
            ctl = next((c for c in r["entries"] if c["technique"] in CONTEXT and (c.get("split_band") or {}).get("ratio")), None)
            if ctl and sb["ratio"] is not None:
                cr = ctl["split_band"]["ratio"]
                L.append(f"| (control) the same band and away pixels in {ctl['label']}, one map without splits | {r['scene']} | "
                         f"band MAE {ctl['split_band']['band_mae']:.4f} / away {ctl['split_band']['away_mae']:.4f} = {cr:.2f}: "
                         f"csm's ratio is {sb['ratio'] / cr:.2f}x the control's | - |")
    for r in seqs:
        a, b = _first(r, "csm"), _entry(r, "csm(stable=False)")
        if a and b:
            fa, fb = a["temporal"]["flicker"], b["temporal"]["flicker"]
            L.append(f"| csm flicker: stable against fitted cascades | {r['scene']} | stable {fa:.5f}, fitted {fb:.5f} "
                     f"({fb / fa if fa > 0 else math.inf:.2f}x) | - |")
    return L


def warnings_text(entries: list[dict]) -> list[str]:
    """The entries' warnings, each text once with the settings that gave it (a warning starts
    ``technique[label:light]: ``)."""
    by: dict[str, list[str]] = {}
    for e in entries:
        for w in e.get("warnings", []):
            by.setdefault(w.split("]: ", 1)[-1], []).append(e["label"])
    return [f"Warning ({', '.join(dict.fromkeys(who))}): {text}" for text, who in sorted(by.items())] + ([""] if by else [])


def plot(row: dict, path: Path) -> None:
    """Penumbra MAE against frame time (log axes), each setting one marker: its technique's hue, a shade and marker per setting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.palette import variant_style

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    seen: dict[str, int] = {}
    for e in row["entries"]:
        k = seen[e["technique"]] = seen.get(e["technique"], -1) + 1
        st = variant_style(e["technique"], k)
        ax.scatter([e["frame_ms"]], [max(e["error"]["mae_penumbra"], 1e-5)], color=st["color"], marker=st["marker"], s=28, label=e["label"])
    ax.axhline(TARGET_MAE, color="grey", linestyle="--", linewidth=0.8, label=f"penumbra MAE {TARGET_MAE}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("frame time (ms)", fontsize=8)
    ax.set_ylabel("penumbra MAE against the reference", fontsize=8)
    ax.set_title(f"{row['scene']} / {row['light'].split('/')[-1]}, {row['width']}x{row['height']}, {row['device']}", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=5, ncol=2, loc="best")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    have, missing = registered()
    preset = rows[0].get("preset", "full") if rows else "full"
    cmd = ctx["command"] if preset in ("full", "quick") else f"{PRESET_ENV}={preset} {ctx['command']}"
    L = [line.replace(f"`{ctx['command']}`", f"`{cmd}`") for line in report_header("worlds", rows, md, ctx | {"command": cmd})]
    L = [line.replace("Times: median of 3 runs after a warm-up.", "Times: frames, the median of the preset's runs after a warm-up "
                      "(`full`: 3, `cpu`: 1); sequences, one run per frame.") for line in L]
    if missing:
        L.append(f"Not registered in this process, so not measured: {', '.join(f'`{t}`' for t in missing)} "
                 f"(of {', '.join(f'`{t}`' for t in TECHNIQUES)}; rerun the command once they are).")
    L.append(f"Preset `{preset}`" + (f" (`${PRESET_ENV}`)" if preset not in ("full", "quick") else "") + "; ground truth: the reference at "
             + ", ".join(sorted({str(r['ground_truth_samples']) for r in rows})) + " samples per frame, seed 0.")
    if any(r["device"] == "cpu" for r in rows):
        L.append("CPU times are Warp's scalar CPU backend (one thread per launch chunk, no SIMD): ratios between techniques may "
                 "reorder on a GPU.")
    loads = [r["machine"]["load"] for r in rows if r.get("machine", {}).get("load") is not None]
    if loads:
        L.append(f"The host's load (1-minute average) as the rows finished: {min(loads):g} to {max(loads):g} on "
                 f"{rows[0]['machine'].get('cores', '?')} cores; above the core count, other work shared the CPU and every time is longer by it.")
    L.append("The ground truth is itself sampled (its samples above): its noise enters every penumbra MAE, the reference at 16 "
             "samples' included.")
    L.append("")
    if not rows:
        md.write_text("\n".join(L) + "\n")
        return
    frames = [r for r in rows if "frames" not in r]
    seqs = [r for r in rows if "frames" in r]
    L += ["## Targets", ""] + target_rows(frames, seqs, have) + [""]
    for r in frames:
        ll = r["light"].split("/")[-1]
        L += [f"## {r['scene']} / {ll} ({r['triangles']:,} triangles)", ""]
        rel = Path("images") / ctx["stem"] / f"{r['scene']}-{ll}-mae.png"
        plot(r, md.parent / rel)
        L += [f"![{r['scene']} penumbra MAE against time]({rel.as_posix()})", ""]
        if r.get("image"):
            L += [f"![{r['scene']} V of each technique]({r['image']})", ""]
        L.append(f"Ground truth: {r['ground_truth_samples']} spp, {r['ground_truth_ms'] / 1e3:.1f} s to render.")
        if r.get("load_s") is not None or r.get("build_s") is not None:
            sec = lambda v: "-" if v is None else f"{v:.1f} s"  # noqa: E731
            L.append(f"Loading the stage ({'instances kept' if r.get('instanced') else 'one triangle soup'}, as the command line loads it): "
                     f"{sec(r.get('load_s'))}; building its device copy (BVHs and arrays, {r['device']}): {sec(r.get('build_s'))}.")
        L.append("")
        L += ["| setting | frame ms | penumbra MAE | MAE | memory | counters |", "|---|---:|---:|---:|---|---|"]
        for e in sorted(r["entries"], key=lambda e: e["frame_ms"]):
            L.append(f"| {e['label']} | {e['frame_ms']:.1f} | {e['error']['mae_penumbra']:.4f} | {e['error']['mae']:.4f} | "
                     f"{memory_text(e['memory'])} | {counters_text(e['technique'], e['counters'])} |")
        L += [""] + warnings_text(r["entries"])
    for r in seqs:
        ll = r["light"].split("/")[-1]
        L += [f"## {r['scene']} / {ll} ({len(r['frames'])} frames, time codes {r['frames'][0]:g}..{r['frames'][-1]:g})", ""]
        L += ["| setting | frame ms (median) | flicker ± se | mean penumbra MAE | memory (last frame) | pages rendered per frame | reused / requested, frames 2.. |",
              "|---|---:|---:|---:|---|---|---|"]
        for e in r["entries"]:
            m = e["temporal"]
            cs = e["counters_frames"]
            pages = ", ".join(str(c["rendered"]) for c in cs) if cs and "rendered" in cs[0] else "-"
            later = [c["reused"] / c["requested"] for c in cs[1:] if c.get("requested")]
            reuse = f"{np.mean(later):.1%} (min {min(later):.1%})" if later else "-"
            L.append(f"| {e['label']} | {np.median(e['frame_ms_frames']):.1f} | {m['flicker']:.5f} ± {m['flicker_se']:.5f} | {m['mae_penumbra']:.4f} | "
                     f"{memory_text(e['memory'])} | {pages} | {reuse} |")
        L += [""] + (["Warnings: " + "; ".join(r["warnings"]), ""] if r.get("warnings") else [])
    md.write_text("\n".join(L) + "\n")
