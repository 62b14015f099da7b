"""``reports/scaling.md`` from the ``scaling`` sweep's rows (:mod:`wsoft.bench.scaling`): per axis a
log-log plot of each technique's time, its fitted exponent beside the one its algorithm implies,
and the memory the largest point held."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RAY_TRACED = ("reference", "rtdenoise")  # visibility by rays through a BVH: about log n in the triangles and instances
AXIS_X = {"triangles": "triangles", "pixels": "pixels", "map": "map texels", "lights": "lights", "instances": "placed instances"}


def size_of(row: dict) -> float:
    """The row's size on its axis: triangles, pixels (w x h), map texels (side²), lights or instances."""
    axis, v = row["axis"], row["value"]
    if axis == "pixels":
        return float(v[0] * v[1])
    if axis == "map":
        return float(v) ** 2
    if axis == "triangles":
        return float(row["triangles"])
    return float(v)


def implied(technique: str, axis: str) -> tuple[float, str]:
    """The exponent of time on ``axis`` that ``technique``'s algorithm implies, and why."""
    if axis == "triangles":
        if technique in RAY_TRACED:
            return 0.0, "rays through a BVH: log n"
        return 1.0, "every caster triangle rasterized or turned into edges and wedges: linear"
    if axis == "instances":
        if technique in RAY_TRACED:
            return 0.0, "a top-level BVH over the instances: log n"
        return 1.0, "every instance in the light's view drawn: linear in instances drawn"
    if axis == "pixels":
        return 1.0, "per-pixel passes: linear in pixels (the map's passes do not grow)"
    if axis == "map":
        return (0.0, "no map") if technique in RAY_TRACED else (1.0, "per-texel passes: linear in texels")
    return 1.0, "each light's passes repeated: linear in lights"


def fit(xs: list[float], ys: list[float]) -> float | None:
    """The least-squares slope of log y on log x (None with fewer than two points)."""
    if len(xs) < 2:
        return None
    return float(np.polyfit(np.log(xs), np.log(np.maximum(ys, 1e-6)), 1)[0])


def write_report(rows: list[dict], md: Path, ctx: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.bench.common import report_header
    from wsoft.palette import style

    L = [line for line in report_header("scaling", rows, md, ctx) if not line.startswith(("Error is against", "penumbra =", "Times:"))]
    L += ["Each row varies one axis of a procedural stage (a perforated, wavy sheet over a ground under rect lights, the same "
          "covered pixels at every size) and runs in a child process of its own. A technique's time is its passes past the "
          "scene and the G-buffer (light maps, its own passes; the reference at 16 samples), the median of 3 alternating "
          "rounds after a warm-up; *implied* is the exponent its algorithm implies; a fitted exponent more than 0.2 above it "
          "is marked **over**. Peak RSS is the process's (the stage, Warp's caches and every earlier technique's leftovers "
          "included); the rise is what the technique's own render added to it. `-`: not run at that point (its time extrapolated from the axis's earlier points passes "
          "60 s; the prediction is in the rows), or refused there (a map beyond its parameter's range, a stage it would need "
          "flattened: the reason is in the rows).", ""]
    for axis in ("triangles", "pixels", "map", "lights", "instances"):
        mine = sorted((r for r in rows if r.get("axis") == axis), key=size_of)
        if not mine:
            continue
        techs = sorted({t for r in mine for t in r["techniques"]})
        L += [f"## Against {AXIS_X[axis]}", "",
              "| technique | " + " | ".join(f"{size_of(r):,.0f}" for r in mine) + " | fitted | implied | |",
              "|---|" + "---:|" * len(mine) + "---:|---:|---|"]
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for t in techs:
            pts = [(size_of(r), r["techniques"][t]["ms"]) for r in mine if t in r["techniques"] and r["techniques"][t].get("ms") is not None]
            k = fit([p[0] for p in pts], [p[1] for p in pts])
            imp, why = implied(t, axis)
            flag = "**over**" if k is not None and k > imp + 0.2 else ""
            cells = []
            for r in mine:
                e = r["techniques"].get(t)
                cells.append("-" if e is None or e.get("ms") is None else f"{e['ms']:.1f}")
            L.append(f"| {t} | " + " | ".join(cells) + f" | {'-' if k is None else f'{k:.2f}'} | {imp:.1f} ({why}) | {flag} |")
            if pts:
                st = style(t)
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=st["marker"], color=st["color"], label=t, lw=1)
        ax.set_xlabel(AXIS_X[axis])
        ax.set_ylabel("technique passes, ms")
        ax.set_title(f"cost against {AXIS_X[axis]}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, ncol=2)
        rel = Path("images") / ctx["stem"] / f"{axis}.png"
        (ctx["out_dir"] / rel).parent.mkdir(parents=True, exist_ok=True)
        fig.tight_layout()
        fig.savefig(ctx["out_dir"] / rel, dpi=110)
        plt.close(fig)
        big = mine[-1]
        L += ["", f"![time against {AXIS_X[axis]}]({rel.as_posix()})", "",
              f"Memory at the largest point ({size_of(big):,.0f} {AXIS_X[axis]}): "
              + "; ".join(f"`{t}` {e['rss_peak_mib']:,.0f} MiB peak RSS (+{e.get('rss_rise_mib', 0.0):,.0f} while it rendered), "
                          f"{e['device_bytes'] / 2**20:,.1f} MiB on the device"
                          for t, e in sorted(big["techniques"].items()) if e.get("ms") is not None and "rss_peak_mib" in e), ""]
    load = sorted((r for r in rows if r.get("axis") == "loading"), key=lambda r: r["triangles"])
    if load:
        L += ["## Loading: the stage on disk to the first pass", "",
              "usd-core's open and read of the sheet's arrays, wsoft's `load_scene` (triangulation, transforms, materials, the "
              "whole of it), the device upload (the BVH build), and embreex building the same triangles (the peer).", "",
              "| triangles | usd-core read s | wsoft load s | upload (BVH) s | embree build s | µs a triangle (load + upload) | peak RSS MiB |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
        for r in load:
            emb = "-" if r.get("embree_build_s") is None else f"{r['embree_build_s']:.3f}"
            L.append(f"| {r['triangles']:,} | {r['usd_read_s']:.3f} | {r['load_s']:.3f} | {r['upload_s']:.3f} | {emb} | "
                     f"{1e6 * (r['load_s'] + r['upload_s']) / r['triangles']:.2f} | {r['rss_peak_mib']:,.0f} |")
        k = fit([r["triangles"] for r in load], [r["load_s"] + r["upload_s"] for r in load])
        if k is not None:
            L += ["", f"Load and upload together grow with exponent {k:.2f} in the triangles (implied: 1.0, linear)."]
    md.write_text("\n".join(L) + "\n")
