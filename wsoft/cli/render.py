"""``wsoft render``: one technique on a stage, to EXR or PNG (and a shaded PNG, stats); with
``--frames``, one output per time code."""

from __future__ import annotations

import json
import os

import wsoft.cli.args as a
from wsoft.cli.common import (
    auto_args, auto_line, check_args, check_output, compile_note, default_output, frames_args, FrameProgress, output_format, output_of,
    parse_sets, print_notes, print_warnings, sequence_line, write_frame,
)
from wsoft.cli.progress import CompileNotice, PassProgress


def add_parser(sub, one_of: str) -> None:
    r = sub.add_parser("render", help="render a stage with a technique, write EXR or PNG (and a shaded PNG, stats)", formatter_class=a.Help)
    a.scene(r)
    r.add_argument("--technique", "-t", required=True, metavar="TECHNIQUE", help=one_of)
    a.sets(r)
    a.auto_options(r)
    a.size(r, "image width in pixels (default: 640, or the render settings' resolution; --width alone keeps their aspect)")
    a.camera(r)
    a.render_settings(r)
    a.light(r, "light path or name for V (default: every shadow-casting light; V = the first)")
    a.instancing(r)
    a.time(r)
    a.frames(r, "a sequence: every time code from A to B (step 1, or STEP) within the stage's range, one output per frame named "
             "out.0012.exr; --stats gets the sequence's summary")
    a.device(r)
    r.add_argument("--pixel-samples", type=a.int_in("--pixel-samples", 1, a.MAX_PIXEL_SAMPLES), default=1, metavar="N",
                   help=f"G-buffer samples per pixel, 1 to {a.MAX_PIXEL_SAMPLES}")
    r.add_argument("--out", help="output file, by its extension: .exr (every channel, float32) or .png (V as 16-bit linear grey) "
                   "(default: the productName of the render settings' product with a visibility RenderVar, else "
                   "<stage>-<technique>.exr in the current folder)")
    r.add_argument("--stats", help="stats JSON")
    r.add_argument("--png", help="shaded PNG (R G B, sRGB)")
    a.subdiv(r)
    a.material_purpose(r)
    r.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.errors import ParameterError

    scene_file = check_args(args, [args.technique])
    for path, what in ((args.out, "--out"), (args.stats, "--stats"), (args.png, "--png")):
        check_output(path, what)
    if args.out:
        output_format(args.out, "--out")
    if args.png and os.path.splitext(args.png)[1].lower() != ".png":
        raise ParameterError(f"--png {args.png}: the shaded image is written as PNG; give a .png name")
    params = parse_sets(args.set, [args.technique])
    params.update(auto_args(args, args.technique))
    if args.frames is not None:
        return _frames(args, scene_file, params)
    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level,
                       material_purpose=args.material_purpose)
    out, why = output_of(scene, args.out, default_output(scene_file, args.technique))
    with CompileNotice(args.device, None if args.technique == "auto" else [args.technique]), PassProgress(args.technique) as progress:
        frame = wsoft.render(
            scene, args.technique, width=args.width, height=args.height, camera=args.camera, light=args.light,
            device=args.device, pixel_samples=args.pixel_samples, progress=progress, **params,
        )
    print_warnings(frame.stats["warnings"])  # the stage's, then the passes'
    chosen = frame.stats["counters"]["techniques"].get("auto", {}) if args.technique == "auto" else {}
    for light, c in chosen.items():
        print(auto_line(light, c["auto"], len(chosen)))
    print_notes(frame.stats["notes"])
    write_frame(frame, out)
    if args.png:
        frame.write_png(args.png)
    if args.stats:
        os.makedirs(os.path.dirname(os.path.abspath(args.stats)), exist_ok=True)
        with open(args.stats, "w") as f:
            json.dump(frame.stats, f, indent=2, default=str)
    st = frame.stats
    print(f"{st['technique']} on {os.path.basename(scene.path)} ({st['width']}x{st['height']}, {st['device']}): "
          f"{st['timings_ms']['total']:.1f} ms{compile_note(st['timings_ms']['compile'])}, passes: {', '.join(st['passes'])}")
    print(f"wrote {out}{why}" + (f", {args.png}" if args.png else "") + (f", {args.stats}" if args.stats else ""))
    return 0


def _frames(args, scene_file: str, params: dict) -> int:
    """``render --frames``: one output (PNG, stats) per time code, named as render delegates number
    frames (``out.0012.exr``); ``--stats`` itself gets the sequence's summary and every frame's costs."""
    import types

    from wsoft.pipeline.sequence import frame_path, render_sequence

    frames_args(args)
    with CompileNotice(args.device, [args.technique]):
        seq = render_sequence(scene_file, args.technique, frames=args.frames, width=args.width, height=args.height,
                              camera=args.camera, light=args.light, device=args.device, pixel_samples=args.pixel_samples,
                              render_settings=args.render_settings, instancing=args.instancing, progress=FrameProgress(),
                              subdiv_level=args.subdiv_level, material_purpose=args.material_purpose, **params)
    first = seq.frames[0]
    rs = seq.render_settings
    out, why = output_of(types.SimpleNamespace(render_settings=rs, path=first.stats["scene"]["path"]), args.out,
                         default_output(scene_file, args.technique))
    print_warnings(seq.warnings + sorted({w for fr in seq.frames for w in fr.stats["warnings"]}))
    print_notes(n for fr in seq.frames for n in fr.stats["notes"])
    for t, fr in zip(seq.times, seq.frames):
        write_frame(fr, frame_path(out, t))
        if args.png:
            fr.write_png(frame_path(args.png, t))
        if args.stats:
            os.makedirs(os.path.dirname(os.path.abspath(args.stats)), exist_ok=True)
            with open(frame_path(args.stats, t), "w") as f:
                json.dump(fr.stats, f, indent=2, default=str)
    if args.stats:
        with open(args.stats, "w") as f:
            json.dump({"times": seq.times, "summary": seq.summary, "frames": seq.stats, "warnings": seq.warnings}, f, indent=2, default=str)
    ms = [fr.stats["timings_ms"]["total"] for fr in seq.frames]
    st = first.stats
    print(f"{st['technique']} on {os.path.basename(st['scene']['path'])} ({st['width']}x{st['height']}, {st['device']}): "
          f"{sum(ms) / len(ms):.1f} ms a frame (min {min(ms):.1f}, max {max(ms):.1f}); {sequence_line(seq)}")
    written = [frame_path(out, seq.times[0])] + ([frame_path(out, seq.times[-1])] if len(seq.times) > 1 else [])
    print(f"wrote {' ... '.join(written)}{why}" + (f", PNGs {frame_path(args.png, seq.times[0])} ..." if args.png else "")
          + (f", {args.stats} and a JSON per frame" if args.stats else ""))
    return 0

