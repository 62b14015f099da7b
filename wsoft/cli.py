"""``wsoft`` command line: render, plan, techniques, bench.

Bad input prints one line naming the file and prim and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys


def _parse_sets(items: list[str] | None) -> dict[str, str]:
    from wsoft.errors import ParameterError

    out = {}
    for item in items or []:
        if "=" not in item:
            raise ParameterError(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def cmd_render(args) -> int:
    import wsoft

    scene = wsoft.load_scene(args.scene, time=args.time)
    params = _parse_sets(args.set)
    frame = wsoft.render(
        scene, args.technique, width=args.width, height=args.height, camera=args.camera, light=args.light,
        device=args.device, pixel_samples=args.pixel_samples, **params,
    )
    frame.write_exr(args.out)
    if args.png:
        frame.write_png(args.png)
    if args.stats:
        os.makedirs(os.path.dirname(os.path.abspath(args.stats)), exist_ok=True)
        with open(args.stats, "w") as f:
            json.dump(frame.stats, f, indent=2, default=str)
    for w in scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    st = frame.stats
    print(f"{st['technique']} on {os.path.basename(scene.path)} ({args.width}x{args.height}, {st['device']}): "
          f"{st['timings_ms']['total']:.1f} ms, passes: {', '.join(st['passes'])}")
    print(f"wrote {args.out}" + (f", {args.png}" if args.png else "") + (f", {args.stats}" if args.stats else ""))
    return 0


def cmd_plan(args) -> int:
    import wsoft

    scene = wsoft.load_scene(args.scene, time=args.time)
    techs = args.technique or None
    p = wsoft.plan(scene, techs, light=args.light)
    if args.json:
        print(json.dumps(p, indent=2))
        return 0
    print(f"scene {p['scene']}: {p['triangles']} triangles, up {p['up_axis']}, {p['meters_per_unit']:g} m/unit")
    print("shadow-casting lights:" + ("" if p["lights"] else " (none)"))
    for l in p["lights"]:
        print(f"  {l['path']:<32} {l['kind']:<8} {l['size']}")
    print("lights skipped:" + ("" if p["skipped_lights"] else " (none)"))
    for l in p["skipped_lights"]:
        print(f"  {l['path']:<32} {l['kind']:<12} {l['reason']}")
    print("cutout (perforated) materials:" + ("" if p["cutout_materials"] else " (none)"))
    for m in p["cutout_materials"]:
        print(f"  {m['path']:<32} {m['triangles']} triangles")
    print(f"dynamic casters: {', '.join(p['dynamic_prims']) or '(none)'}")
    print(f"triangles with baked light: {p['baked_light_triangles']}")
    for w in p["warnings"]:
        print(f"warning: {w}")
    for name, passes in p["techniques"].items():
        print(f"{name}: {' -> '.join(passes)}")
    return 0


def cmd_techniques(args) -> int:
    from wsoft.techniques import TECHNIQUES

    desc = [TECHNIQUES[n].describe() for n in sorted(TECHNIQUES)]
    if args.json:
        print(json.dumps(desc, indent=2, default=str))
        return 0
    for d in desc:
        print(f"{d['name']}: {d['summary']}")
        print(f"  reads: {', '.join(d['reads'])}; writes: {', '.join(d['writes'])}")
        for p in d["parameters"]:
            print(f"  {p['name']:<16} {p['type']:<6} default {p['default']!s:<8} {p['meaning']}")
    return 0


def cmd_compare(args) -> int:
    """Render a technique and the reference on the same view; write EXR/PNG of both and a stats table."""
    import wsoft
    from wsoft.io import write_gray_png
    from wsoft.metrics import visibility_error

    scene = wsoft.load_scene(args.scene, time=args.time)
    params = _parse_sets(args.set)
    common = dict(width=args.width, height=args.height, camera=args.camera, light=args.light, device=args.device)
    frame = wsoft.render(scene, args.technique, **common, **params)
    ref = wsoft.render(scene, "reference", **common, samples=args.samples)
    os.makedirs(args.out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(scene.path))[0]
    out = {}
    for name, fr in ((args.technique, frame), ("reference", ref)):
        base = os.path.join(args.out_dir, f"{stem}-{name}")
        fr.write_exr(base + ".exr")
        fr.write_png(base + ".png")
        write_gray_png(base + "-V.png", fr.V)
        with open(base + ".json", "w") as f:
            json.dump(fr.stats, f, indent=2, default=str)
        out[name] = base
    err = visibility_error(frame.V, ref.V, ref["V_stderr"], ref["A"])
    rows = [("pass", args.technique, "reference")]
    names = list(dict.fromkeys(frame.stats["passes"] + ref.stats["passes"])) + ["total"]
    for n in names:
        a = frame.stats["timings_ms"].get(n)
        b = ref.stats["timings_ms"].get(n)
        rows.append((n, f"{a:.1f}" if a is not None else "-", f"{b:.1f}" if b is not None else "-"))
    table = ["| " + " | ".join(r) + " |" for r in rows]
    table.insert(1, "|---|---:|---:|")
    lines = [f"# {args.technique} vs reference on {stem} ({args.width}x{args.height}, {frame.stats['device']}, light {frame.stats['light']})", "",
             f"Command: `wsoft compare {' '.join(sys.argv[2:]) if sys.argv[1:2] == ['compare'] else args.scene}`", "",
             "## Time (ms)", "", *table, "", "## Error of V against the reference", "",
             "| MAE | RMSE | max | MAE penumbra | penumbra pixels | >3 stderr |", "|---:|---:|---:|---:|---:|---:|",
             f"| {err['mae']:.4f} | {err['rmse']:.4f} | {err['max']:.3f} | {err['mae_penumbra']:.4f} | {err['penumbra_pixels']} | {err.get('frac_outside_3se', 0):.3f} |"]
    md = os.path.join(args.out_dir, f"{stem}-{args.technique}-vs-reference.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nwrote {out[args.technique]}.exr/.png/.json, {out['reference']}.exr/.png/.json, {md}")
    return 0


def cmd_bench(args) -> int:
    from wsoft.bench.harness import run_sweep

    return run_sweep(args.sweep, quick=args.quick, device=args.device, out_dir=args.out_dir, fresh=args.fresh)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="wsoft", description="Soft-shadow techniques in Warp on USD stages.")
    sub = ap.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("render", help="render a stage with a technique, write EXR (and PNG, stats)")
    r.add_argument("scene")
    r.add_argument("--technique", "-t", required=True)
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="technique parameter (repeatable)")
    r.add_argument("--width", type=int, default=640)
    r.add_argument("--height", type=int, default=480)
    r.add_argument("--camera", help="camera prim path (default: the stage's first camera, else automatic)")
    r.add_argument("--light", help="light path or name for V (default: every shadow-casting light; V = the first)")
    r.add_argument("--time", type=float, help="USD time code (default: the stage's start time)")
    r.add_argument("--device", help="cpu or cuda:N (default: cuda:0 when available, else cpu)")
    r.add_argument("--pixel-samples", type=int, default=1, help="G-buffer samples per pixel")
    r.add_argument("--out", required=True, help="output EXR")
    r.add_argument("--stats", help="stats JSON")
    r.add_argument("--png", help="shaded PNG")
    r.set_defaults(fn=cmd_render)

    c = sub.add_parser("compare", help="render a technique and the reference; EXR/PNG of both and a stats table")
    c.add_argument("scene")
    c.add_argument("--technique", "-t", default="hard")
    c.add_argument("--set", action="append", metavar="KEY=VALUE")
    c.add_argument("--samples", type=int, default=256, help="reference light samples per pixel")
    c.add_argument("--width", type=int, default=640)
    c.add_argument("--height", type=int, default=480)
    c.add_argument("--camera")
    c.add_argument("--light")
    c.add_argument("--time", type=float)
    c.add_argument("--device")
    c.add_argument("--out-dir", default="out")
    c.set_defaults(fn=cmd_compare)

    p = sub.add_parser("plan", help="lights, cutouts and the passes each technique would run")
    p.add_argument("scene")
    p.add_argument("--technique", "-t", action="append")
    p.add_argument("--light")
    p.add_argument("--time", type=float)
    p.add_argument("--json", action="store_true")
    p.set_defaults(fn=cmd_plan)

    t = sub.add_parser("techniques", help="techniques and their parameters")
    t.add_argument("--json", action="store_true")
    t.set_defaults(fn=cmd_techniques)

    b = sub.add_parser("bench", help="run a benchmark sweep; rows go to reports/<sweep>.jsonl")
    b.add_argument("sweep")
    b.add_argument("--quick", action="store_true", help="the CI-sized version")
    b.add_argument("--device", action="append", help="device(s) to sweep (default: the default device)")
    b.add_argument("--out-dir", default="reports")
    b.add_argument("--fresh", action="store_true", help="discard earlier rows instead of resuming")
    b.set_defaults(fn=cmd_bench)

    args = ap.parse_args(argv)
    from wsoft.errors import WsoftError

    try:
        return int(args.fn(args) or 0)
    except WsoftError as exc:
        print(f"wsoft: error: {exc.line()}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output that cannot be written, a full disk...
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"wsoft: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("wsoft: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
