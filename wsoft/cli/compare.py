"""``wsoft compare``: techniques and the reference in one frame graph; each one's images and stats,
a grid image of them all, a time and error table; with ``--frames``, the temporal measures."""

from __future__ import annotations

import json
import os
import sys

import wsoft.cli.args as a
from wsoft.cli.common import (
    auto_args, auto_line, check_args, check_output, frames_args, FrameProgress, parse_sets, print_notes, print_warnings, sequence_line,
)
from wsoft.cli.progress import CompileNotice, PassProgress


def add_parser(sub, one_of: str) -> None:
    c = sub.add_parser("compare", help="render techniques and the reference in one graph; EXR/PNG of each, a grid image, a time and error table",
                       formatter_class=a.Help, description="Writes OUT_DIR/<stage>-<technique>.exr/.png/-V.png/.json per technique, "
                       "<stage>-<technique>-flip.png (its ꟻLIP map against the reference, magma) per technique compared, "
                       "OUT_DIR/<stage>-compare.png (every technique's shaded image and its difference from the reference's V, "
                       "titled with its parameters, frame ms and penumbra MAE, a row per light) "
                       "and OUT_DIR/<stage>-compare.md (times and errors against the reference: MAE of V, ꟻLIP of the shaded image).")
    a.scene(c)
    c.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE", help="a technique (repeatable; default: hard); " + one_of)
    a.auto_options(c)
    a.sets(c, "[TECHNIQUE.]KEY=VALUE", "a parameter (TECHNIQUE.KEY with several techniques)")
    c.add_argument("--samples", type=a.int_in("--samples", 1), default=256, metavar="N", help="reference light samples per pixel")
    a.size(c)
    a.camera(c)
    a.render_settings(c)
    a.light(c, "light path or name whose V is compared (default: every shadow-casting light)")
    a.instancing(c)
    a.time(c)
    a.frames(c, "a sequence: every time code from A to B (step 1, or STEP) within the stage's range; adds flicker against the "
             "reference and each frame's error (<stage>-compare.md, <stage>-sequence.json)")
    a.device(c)
    c.add_argument("--out-dir", default="out", help="where the images, stats and the compare table are written")
    a.subdiv(c)
    a.material_purpose(c)
    c.set_defaults(fn=run)


def _technique_sets(names: list[str], sets: list[str] | None) -> list[tuple[str, dict]]:
    """``-t`` names with their ``--set`` values: ``name.key=value`` for one of them, ``key=value``
    for the only one."""
    from wsoft.errors import ParameterError

    params: dict[str, dict] = {n: {} for n in names}
    for k, v in parse_sets(sets, names).items():
        if "." in k and k.split(".", 1)[0] in params:
            t, key = k.split(".", 1)
            params[t][key] = v
        elif len(names) == 1:
            params[names[0]][k] = v
        else:
            raise ParameterError(f"--set {k}={v}: with several techniques write TECHNIQUE.{k}={v}")
    return [(n, params[n]) for n in names]


def _short_table(frames, reference: str | None) -> list[str]:
    """Markdown rows: each technique's frame ms, MAE and penumbra MAE, the reference first; with
    several lights, a row per technique and light."""
    several = any(len(frames[l].stats.get("errors") or {}) > 1 for l in frames)
    if not several:
        rows = ["| technique | frame ms | MAE | penumbra MAE |", "|---|---:|---:|---:|"]
    else:
        rows = ["| technique | light | frame ms | MAE | penumbra MAE |", "|---|---|---:|---:|---:|"]
    for label in sorted(frames, key=lambda l: l != reference):
        st = frames[label].stats
        ms = f"{st['timings_ms']['total']:.1f}"
        if not several:
            e = st.get("error")
            rows.append(f"| {label} | {ms} | " + (f"{e['mae']:.4f} | {e['mae_penumbra']:.4f} |" if e else "- | - |"))
            continue
        errors = st.get("errors") or {}
        for light in errors or ["-"]:
            e = errors.get(light)
            rows.append(f"| {label} | {light} | {ms} | " + (f"{e['mae']:.4f} | {e['mae_penumbra']:.4f} |" if e else "- | - |"))
    return rows


def run(args) -> int:
    """Render techniques and the reference in one graph; write EXR/PNG of each, each technique's ꟻLIP
    map (magma), one grid image of them all beside the reference and a time / error table."""
    check_output(args.out_dir, "--out-dir", folder=True)
    names = list(dict.fromkeys(args.technique or ["hard"]))
    scene_file = check_args(args, names)
    techs = _technique_sets(names, args.set)
    auto = auto_args(args, "auto" if "auto" in names else None)
    techs = [(n, {**p, **auto}) if n == "auto" else (n, p) for n, p in techs]
    if args.frames is not None:
        return _frames(args, techs, scene_file)
    import wsoft
    from wsoft.io import write_gray_png
    from wsoft.metrics.figures import write_compare_grid
    from wsoft.metrics.flip import write_flip_png
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level,
                       material_purpose=args.material_purpose)
    with CompileNotice(args.device, None if "auto" in names else names + ["reference"]), PassProgress("compare") as progress:
        fs = wsoft.compare(scene, techs, samples=args.samples, width=args.width, height=args.height, camera=args.camera, light=args.light,
                           device=args.device, progress=progress)
    chosen = fs["auto"].stats["counters"]["techniques"].get("auto", {}) if "auto" in fs else {}
    for light, c in chosen.items():
        print(auto_line(light, c["auto"], len(chosen)))
    os.makedirs(args.out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(scene.path))[0]
    written = []
    for label, fr in fs.items():
        base = os.path.join(args.out_dir, f"{stem}-{label}")
        fr.write_exr(base + ".exr")
        fr.write_png(base + ".png")
        write_gray_png(base + "-V.png", fr.V)
        with open(base + ".json", "w") as f:
            json.dump(fr.stats, f, indent=2, default=str)
        if "flip" in fr.error_maps:
            write_flip_png(base + "-flip.png", fr.error_maps["flip"])
        written.append(base + ".exr/.png/-V.png/.json" + ("/-flip.png" if "flip" in fr.error_maps else ""))
    grid = os.path.join(args.out_dir, f"{stem}-compare.png")
    write_compare_grid(grid, fs)
    labels = list(fs)
    gstats = fs.stats
    shared = gstats["shared_passes"]
    rows = [("pass", "kind", *labels)]
    for n in gstats["passes"]:
        cells = []
        for label in labels:
            ms = fs[label].stats["timings_ms"].get(n)
            if ms is None and gstats["pass_kinds"][n] == "metric" and (n.startswith(f"error[{label}:") or n == f"flip[{label}]"):
                ms = gstats["timings_ms"][n]
            cells.append("-" if ms is None else f"{ms:.1f}" + (" (shared)" if n in shared and label in shared[n] else ""))
        rows.append((n, gstats["pass_kinds"][n], *cells))
    rows.append(("frame (its passes)", "", *[f"{fs[l].stats['timings_ms']['total']:.1f}" for l in labels]))
    rows.append(("kernel compilation (not in the times above)", "", *[f"{fs[l].stats['timings_ms']['compile']:.1f}" for l in labels]))
    table = ["| " + " | ".join(r) + " |" for r in rows]
    table.insert(1, "|---|---|" + "---:|" * len(labels))
    err_rows = ["| technique | light | MAE | RMSE | max | MAE penumbra | penumbra pixels | MAE facing | MAE not facing | >3 stderr | NaN | "
                "ꟻLIP | ꟻLIP covered |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label in labels:
        for light, e in fs[label].stats.get("errors", {}).items():
            flip = f"{e['flip']:.4f} | {e['flip_covered']:.4f}" if "flip" in e else "- | -"
            err_rows.append(f"| {label} | {light} | {e['mae']:.4f} | {e['rmse']:.4f} | {e['max']:.3f} | {e['mae_penumbra']:.4f} | {e['penumbra_pixels']} | "
                            f"{e['facing']['mae']:.4f} | {e['not_facing']['mae']:.4f} | {e.get('frac_outside_3se', 0):.3f} | {e['nan_pixels']} | {flip} |")
    cmd = "wsoft " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["compare"] else f"wsoft compare {args.scene}"
    ref = gstats["reference"]
    several = any(len(fs[l].stats["light_labels"]) > 1 for l in labels if l != ref)
    lines = [f"# {', '.join(l for l in labels if l != ref)} vs {ref} on {stem} ({gstats['width']}x{gstats['height']}, {gstats['device']})", "",
             f"Command: `{cmd}`", "", *_short_table(fs, ref), "",
             f"![each technique beside the reference]({os.path.basename(grid)})", "",
             f"`{os.path.basename(grid)}`: each technique's shaded image, its ꟻLIP map (magma, 0 to 1) and its V minus the reference's "
             "(red: lighter, blue: darker)" + (", a row for each light." if several else "."), "",
             "One frame graph: passes marked *shared* ran once for several techniques; a technique's frame time counts every pass it needs.", "",
             "## Time (ms)", "", *table, "",
             f"Kernel compilation: {gstats['timings_ms']['compile']:.1f} ms for the whole graph (Warp compiles or loads a module at its first launch; "
             "seconds with a cold kernel cache), excluded from every pass time and frame total above.", "",
             f"## Error of V against `{ref}` (the metric pass, on the same pixels)", "", *err_rows, "",
             "ꟻLIP: NVIDIA's perceptual difference of the shaded images as the PNGs show them (LDR, 67 pixels per degree), "
             "its mean over the whole image and over the covered pixels; one image per technique, so every light of a technique "
             f"has the same value. Its map: `{stem}-<technique>-flip.png` (magma)."]
    md = os.path.join(args.out_dir, f"{stem}-compare.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    print_warnings(sorted({w for fr in fs.values() for w in fr.stats["warnings"]}))
    print_notes(n for fr in fs.values() for n in fr.stats["notes"])
    print(f"\nwrote {', '.join(written)}, {grid}, {md}")
    return 0


def _frames(args, techs, scene_file: str) -> int:
    """``compare --frames``: per time code each technique's EXR/PNG/JSON (``<stage>-<label>.0012.exr``),
    ``<stage>-compare.md`` / ``<stage>-sequence.json`` with the temporal measures (flicker against
    the reference, mean and worst error) and each frame's times and errors, and ``<stage>-compare.png``,
    the first frame's grid (:func:`wsoft.metrics.figures.write_compare_grid`)."""
    from wsoft.metrics.figures import write_compare_grid
    from wsoft.metrics.sequences import compare_sequence
    from wsoft.pipeline.sequence import frame_path

    frames_args(args)
    with CompileNotice(args.device, [n for n, _ in techs] + ["reference"]):
        seq = compare_sequence(scene_file, techs, frames=args.frames, samples=args.samples, width=args.width, height=args.height,
                               camera=args.camera, light=args.light, device=args.device, render_settings=args.render_settings,
                               instancing=args.instancing, progress=FrameProgress(), subdiv_level=args.subdiv_level,
                               material_purpose=args.material_purpose)
    os.makedirs(args.out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(seq.frames[0].stats["scene"]["path"]))[0]
    labels = list(seq.frames[0])
    for t, fs in zip(seq.times, seq.frames):
        for label, fr in fs.items():
            base = os.path.join(args.out_dir, f"{stem}-{label}.exr")
            fr.write_exr(frame_path(base, t))
            fr.write_png(frame_path(base[:-4] + ".png", t))
            with open(frame_path(base[:-4] + ".json", t), "w") as f:
                json.dump(fr.stats, f, indent=2, default=str)
    t0 = seq.times[0]
    grid = os.path.join(args.out_dir, f"{stem}-compare.png")
    write_compare_grid(grid, seq.frames[0], seq.ground_truths[0], reference_ms=seq.stats[0].get("ground_truth_ms"),
                       title=f"{stem} at time {t0:g} (the first frame): {seq.frames[0].stats['width']}x{seq.frames[0].stats['height']}, "
                             f"{seq.frames[0].stats['device']}")
    temporal = seq.summary["temporal"]
    static = any("temporal_std" in m for per in temporal.values() for m in per.values())
    head = "| technique | light | mean MAE | mean penumbra MAE | worst frame (penumbra MAE) | flicker | own change | reference change |"
    head += " temporal std |" if static else ""
    rows = [head, "|---|---|---:|---:|---|---:|---:|---:|" + ("---:|" if static else "")]
    for label in labels:
        for ll, m in temporal[label].items():
            w = m.get("worst_frame", {})
            rows.append(f"| {label} | {ll} | {m['mae']:.4f} | {m['mae_penumbra']:.4f} | {w.get('time', 0):g} ({w.get('mae_penumbra', 0):.4f}) | "
                        f"{m['flicker']:.5f} | {m['change']:.5f} | {m['reference_change']:.5f} |"
                        + (f" {m.get('temporal_std', 0):.5f} |" if static else ""))
    noise = next((m.get("flicker_noise") for per in temporal.values() for m in per.values()), None)
    per_frame = ["| time | " + " | ".join(f"{l} ms | {l} penumbra MAE" for l in labels) + " |",
                 "|---:|" + "---:|---:|" * len(labels)]
    for t, fs in zip(seq.times, seq.frames):
        per_frame.append(f"| {t:g} | " + " | ".join(f"{fs[l].stats['timings_ms']['total']:.1f} | {fs[l].stats['error']['mae_penumbra']:.4f}"
                                                   for l in labels) + " |")
    cmd = "wsoft " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["compare"] else f"wsoft compare {args.scene} --frames {args.frames}"
    lines = [f"# {', '.join(labels)} over {len(seq.times)} frames of {stem} ({seq.frames[0].stats['width']}x{seq.frames[0].stats['height']}, "
             f"{seq.frames[0].stats['device']})", "", f"Command: `{cmd}`", "",
             f"Against the reference at {seq.summary['ground_truth_samples']} light samples in every frame (seed 0). Flicker: the mean over "
             "pixels and frame pairs of |ΔV − ΔV_ref| at the same surface point (the same pixel while the camera stands still, else the "
             "pixel of the previous frame that saw the same world point; disocclusions left out); own change: mean |ΔV|; reference "
             "change: mean |ΔV_ref|." + (f" The reference's own noise floor (from its standard errors): {noise:.5f}." if noise is not None else "")
             + (" The stage authors no time sample: temporal std is each pixel's standard deviation over the frames (a stochastic "
                "technique's crawl; the reference's own is in `" + stem + "-sequence.json`)." if static else ""), "",
             "## Over the sequence", "", *rows, "", f"![the first frame beside the reference]({os.path.basename(grid)})", "",
             f"`{os.path.basename(grid)}`: the first frame (time {t0:g}), each technique's shaded image and its V minus the reference's "
             "(red: lighter, blue: darker).", "", f"Scene: {sequence_line(seq)}.", "", "## Per frame", "", *per_frame]
    md = os.path.join(args.out_dir, f"{stem}-compare.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    js = os.path.join(args.out_dir, f"{stem}-sequence.json")
    with open(js, "w") as f:
        json.dump({"times": seq.times, "summary": seq.summary, "frames": seq.stats, "warnings": seq.warnings}, f, indent=2, default=str)
    print("\n".join(lines))
    print_warnings(seq.warnings + sorted({w for fs in seq.frames for fr in fs.values() for w in fr.stats["warnings"]}))
    print_notes(n for fs in seq.frames for fr in fs.values() for n in fr.stats["notes"])
    print(f"\nwrote {len(seq.times)} frames of {', '.join(labels)} ({stem}-<technique>{frame_path('', seq.times[0])}.exr/.png/.json ...), "
          f"{grid}, {md}, {js}")
    return 0
