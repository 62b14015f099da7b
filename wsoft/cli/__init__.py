"""``wsoft`` command line: render, compare, plan, techniques, scenes, bake, bench, warmup.

Bad input prints one line naming the file and prim and exits with code 2. Warp and USD are
imported by the commands that need them, never to parse or check the arguments (``wsoft --help``
and argument errors answer at once: an unknown technique, scene, sweep or device, an output
whose extension names no format wsoft writes). When Warp is about to compile kernels (a cold
kernel cache), one line on stderr says so with a rough time (:class:`CompileNotice`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import threading
import time

OUTPUT_FORMATS = {".exr": "every channel, float32", ".png": "V as 16-bit linear grey"}
"""What ``render --out`` (or a render product's ``productName``) writes, by extension."""


def _parse_sets(items: list[str] | None) -> dict[str, str]:
    from wsoft.errors import ParameterError

    out = {}
    for item in items or []:
        if "=" not in item:
            raise ParameterError(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


class _Help(argparse.HelpFormatter):
    """Help that shows each option's default when it has one (not None / False)."""

    def _get_help_string(self, action):
        h = action.help or ""
        if action.default not in (None, False, argparse.SUPPRESS) and "default" not in h and action.option_strings:
            h += (" " if h else "") + "(default: %(default)s)"
        return h

    def _split_lines(self, text, width):
        """Lines broken at spaces only: a name such as ``usd-pipeline`` stays whole."""
        import textwrap

        return textwrap.wrap(self._whitespace_matcher.sub(" ", text).strip(), width, break_on_hyphens=False)


def check_output(path: str | None, what: str, *, folder: bool = False) -> None:
    """Fail before any rendering when ``path`` cannot be written: it names a folder (or, for
    ``folder``, a file), a parent is a file, or the nearest existing parent is not writable."""
    from wsoft.errors import ParameterError

    if not path:
        return
    p = os.path.abspath(path)
    if folder:
        if os.path.exists(p) and not os.path.isdir(p):
            raise ParameterError(f"{what} {path}: exists and is not a directory")
    elif os.path.isdir(p):
        raise ParameterError(f"{what} {path}: is a directory, not a file")
    parent = p if folder else os.path.dirname(p)
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        raise ParameterError(f"{what} {path}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK) or (os.path.exists(p) and not os.access(p, os.W_OK)):
        raise ParameterError(f"{what} {path}: permission denied")


class PassProgress:
    """A progress bar over the frame graph's passes (the ``progress`` callable of
    :func:`wsoft.render` and :func:`wsoft.compare`), on stderr.

    Shown only when stderr is a terminal and the render has run :attr:`delay_s` seconds, so short
    renders and piped or redirected output stay quiet; a ticker redraws it (elapsed time) during a
    long pass such as the reference's. Use it as a context manager."""

    delay_s = 2.0

    def __init__(self, desc: str, stream=None):
        self.desc = desc
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(isatty and isatty())
        self.bar = None
        self._pass: str | None = None
        self._compiling: str | None = None
        self._start = time.monotonic()
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None

    def __call__(self, done: int, total: int, name: str | None) -> None:
        if not self.enabled:
            return
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self.desc, file=self.stream, leave=False, dynamic_ncols=True,
                            delay=max(0.0, self.delay_s - (time.monotonic() - self._start)),
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} passes [{elapsed}{postfix}]")  # no rate: passes differ
            self._ticker = threading.Thread(target=self._tick, name="wsoft-progress", daemon=True)
            self._ticker.start()
        self._pass, self._compiling = name, None
        self.bar.set_postfix_str(name or "done", refresh=False)
        self.bar.update(done - self.bar.n)

    def compiling(self, module: str) -> None:
        """Show that Warp compiles ``module`` during the current pass."""
        self._compiling = module
        if self.bar is not None:
            shown = time.monotonic() - self._start >= self.delay_s  # the bar is on the screen: say it at once
            self.bar.set_postfix_str(f"{self._pass or ''} (compiling {module})", refresh=shown)

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            if time.monotonic() - self._start >= self.delay_s:
                self.bar.refresh()

    def close(self) -> None:
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> "PassProgress":
        global _PROGRESS
        _PROGRESS = self
        return self

    def __exit__(self, *exc) -> None:
        global _PROGRESS
        _PROGRESS = None
        self.close()


_PROGRESS: PassProgress | None = None  # the bar shown now, which CompileNotice tells what compiles


class CompileNotice:
    """While it is entered, the first time Warp is about to compile a module (its binary is not in
    the kernel cache) one line goes to stderr: ``compiling kernels for cpu (first run only, ~12 s)``,
    the time a rough estimate from the modules not yet compiled for the device
    (:func:`wsoft.parallel.uncached_seconds`; other techniques' own modules left out when
    ``techniques`` names the ones that run). The progress bar, when shown, names each module that
    compiles. A warm cache prints nothing."""

    def __init__(self, device: str | None, techniques: list[str] | None = None, stream=None):
        from wsoft.parallel import resolve_device, uncached_seconds
        from wsoft.techniques import NAMES, TECHNIQUES

        TECHNIQUES  # noqa: B018  (the technique modules define their kernels on import)
        self.device = resolve_device(device)
        skip = () if techniques is None else tuple(f"wsoft.techniques.{n}" for n in NAMES if n not in techniques)
        self.seconds = uncached_seconds(self.device, skip)
        self.stream = stream if stream is not None else sys.stderr
        self.said = False
        self._lock = threading.Lock()
        self._remove = None

    def __call__(self, module: str, device: str) -> None:
        with self._lock:
            if not self.said:
                self.said = True
                about = f", ~{max(1, round(self.seconds))} s" if self.seconds else ""
                print(f"compiling kernels for {device} (first run only{about})", file=self.stream, flush=True)
        if _PROGRESS is not None:
            _PROGRESS.compiling(module)

    def __enter__(self) -> "CompileNotice":
        from wsoft.parallel import on_compile

        self._remove = on_compile(self)
        return self

    def __exit__(self, *exc) -> None:
        self._remove()


def check_device(name: str | None) -> None:
    """A device name wsoft takes (``cpu``, ``cuda``, ``cuda:N``, ``auto``; None: the default),
    checked without Warp; whether that CUDA device exists is known once Warp starts."""
    from wsoft.errors import ParameterError

    if name is not None and name not in ("cpu", "cuda", "auto") and not re.fullmatch(r"cuda:\d+", name):
        raise ParameterError(f"unknown device {name!r}; use cpu or cuda:N")


def output_format(path: str, what: str, file: str | None = None, prim: str | None = None) -> str:
    """The extension of ``path`` (``.exr`` or ``.png``, :data:`OUTPUT_FORMATS`); any other is an
    error (naming ``file`` and ``prim`` when the name comes from a stage)."""
    from wsoft.errors import ParameterError

    ext = os.path.splitext(path)[1].lower()
    if ext not in OUTPUT_FORMATS:
        raise ParameterError(f"{what} {path}: {'no extension' if not ext else ext + ' is not a format wsoft writes'}; "
                             + "; ".join(f"{e}: {w}" for e, w in OUTPUT_FORMATS.items()), file=file, prim=prim)
    return ext


def scene_arg(arg: str) -> str:
    """A stage path, or the name of a bundled stage (``box_plane``) when no such file exists; an
    unknown name is an error suggesting the closest (:func:`wsoft.usd_scenes.resolve`)."""
    from wsoft import usd_scenes

    return usd_scenes.resolve(arg)


def output_of(scene, out: str | None, default: str) -> tuple[str, str]:
    """The file to write and why that one: ``--out``, else the ``productName`` of the render
    settings' output product (the one with a ``visibility`` RenderVar; a relative name is relative
    to the current folder), else ``default`` (``<stage>-<technique>.exr`` in the current folder).
    Its extension says the format (:func:`output_format`)."""
    if out:
        return out, ""
    rs = scene.render_settings
    product = rs.output if rs is not None else None
    if product is None or not product.product_name:
        why = ("no render settings" if rs is None else f"render settings {rs.path} have no product with a visibility RenderVar"
               if product is None else f"render product {product.path} has no productName")
        check_output(default, "the default output")
        return default, f" (no --out and {why}: named after the stage and technique)"
    what = f"productName of {product.path}"
    check_output(product.product_name, what)
    output_format(product.product_name, "productName", file=scene.path, prim=product.path)
    return product.product_name, f" (the {what})"


def write_frame(frame, path: str) -> None:
    """``frame`` to ``path`` in the format its extension names (:data:`OUTPUT_FORMATS`)."""
    if path.lower().endswith(".png"):
        frame.write_v_png(path)
    else:
        frame.write_exr(path)


def _default_output(scene_file: str, technique: str) -> str:
    return f"{os.path.splitext(os.path.basename(scene_file))[0]}-{technique}.exr"


def _check_args(args, techniques: list[str]) -> str:
    """What a command can check before Warp or USD starts (the technique names, the device, the
    scene); the stage's file."""
    from wsoft.techniques import check_names

    check_names([t for t in techniques if t != "auto"])  # auto: wsoft.auto chooses among the registered ones
    check_device(getattr(args, "device", None))
    return scene_arg(args.scene)


def cmd_render(args) -> int:
    from wsoft.errors import ParameterError

    scene_file = _check_args(args, [args.technique])
    for path, what in ((args.out, "--out"), (args.stats, "--stats"), (args.png, "--png")):
        check_output(path, what)
    if args.out:
        output_format(args.out, "--out")
    if args.png and os.path.splitext(args.png)[1].lower() != ".png":
        raise ParameterError(f"--png {args.png}: the shaded image is written as PNG; give a .png name")
    params = _parse_sets(args.set)
    params.update(_auto_args(args, args.technique))
    if args.frames is not None:
        return _render_frames(args, scene_file, params)
    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level)
    out, why = output_of(scene, args.out, _default_output(scene_file, args.technique))
    with CompileNotice(args.device, None if args.technique == "auto" else [args.technique]), PassProgress(args.technique) as progress:
        frame = wsoft.render(
            scene, args.technique, width=args.width, height=args.height, camera=args.camera, light=args.light,
            device=args.device, pixel_samples=args.pixel_samples, progress=progress, **params,
        )
    for w in frame.stats["warnings"]:  # the stage's, then the passes'
        print(f"warning: {w}", file=sys.stderr)
    for light, c in frame.stats["counters"]["techniques"].get("auto", {}).items() if args.technique == "auto" else ():
        print(_auto_line(light, c["auto"]))
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
          f"{st['timings_ms']['total']:.1f} ms{_compile_note(st['timings_ms']['compile'])}, passes: {', '.join(st['passes'])}")
    print(f"wrote {out}{why}" + (f", {args.png}" if args.png else "") + (f", {args.stats}" if args.stats else ""))
    return 0


def _auto_args(args, technique) -> dict:
    """``--budget-ms``, ``--target-error``, ``--target-flip``, ``--target-flicker``, ``--auto-model`` as
    ``auto``'s parameters (an error with another technique, with no goal or two, or a goal that is
    not a positive finite number)."""
    from wsoft.errors import ParameterError

    goals = ("budget_ms", "target_error", "target_flip", "target_flicker")
    given = {k: getattr(args, k, None) for k in goals}
    given["model"] = getattr(args, "auto_model", None)
    given = {k: v for k, v in given.items() if v is not None}
    if given and technique != "auto":
        raise ParameterError(f"--{next(iter(given)).replace('_', '-').replace('model', 'auto-model')} goes with --technique auto")
    if technique == "auto":
        from wsoft.auto.model import goal_of

        if not any(k in given for k in goals):
            raise ParameterError("--technique auto needs --budget-ms MS, --target-error MAE, --target-flip FLIP or --target-flicker F")
        goal_of(**{k: given[k] for k in goals if k in given})
        import wsoft.auto  # noqa: F401  (registers technique auto with the pipeline)
    return given


def _auto_line(light: str, a: dict) -> str:
    """``auto: Light: pcss(...) (predicted 12.0 ms, penumbra MAE 0.031; runner-up ...)``."""
    c, r = a["choice"], a["runner_up"]
    (k, v), = a["goal"].items()
    goal = f"budget {v:g} ms" if k == "budget_ms" else f"target {k[len('target_'):]} {v:g}"
    q = "error" if k in ("budget_ms", "target_error") else k[len("target_"):]
    return (f"auto ({goal}): {light}: {c['setting']} (predicted {c['predicted_ms']:.1f} ms, {q} {c['predicted_' + q]:.4f})"
            + (f"; runner-up {r['setting']} ({r['predicted_ms']:.1f} ms, {r['predicted_' + q]:.4f})" if r else "")
            + f"; of {len(a['candidates'])} candidates")


def _frames_args(args) -> None:
    """``--frames`` and ``--time`` exclude each other."""
    from wsoft.errors import ParameterError

    if args.time is not None:
        raise ParameterError(f"--time {args.time:g} and --frames {args.frames}: give one of them")


class _FrameProgress:
    """One line per finished frame on stderr: ``frame 12 (3/24): 0.21 s``."""

    def __init__(self):
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int, t: float) -> None:
        now = time.perf_counter()
        print(f"frame {t:g} ({done}/{total}): {now - self.t0:.2f} s", file=sys.stderr)
        self.t0 = now


def _sequence_line(seq) -> str:
    s = seq.summary
    how = ", ".join(f"{s[k]} {w}" for k, w in (("scene_built", "built"), ("scene_refit", "refit"), ("scene_reused", "reused")) if s[k])
    return (f"{s['frames']} frame(s), time codes {seq.times[0]:g}..{seq.times[-1]:g}; scene on the device: {how} "
            f"(load {s['load_ms'] / 1e3:.2f} s, upload {s['upload_ms']:.0f} ms, refit {s['refit_ms']:.0f} ms in all)")


def _render_frames(args, scene_file: str, params: dict) -> int:
    """``render --frames``: one output (PNG, stats) per time code, named as render delegates number
    frames (``out.0012.exr``); ``--stats`` itself gets the sequence's summary and every frame's costs."""
    import types

    from wsoft.pipeline.sequence import frame_path, render_sequence

    _frames_args(args)
    with CompileNotice(args.device, [args.technique]):
        seq = render_sequence(scene_file, args.technique, frames=args.frames, width=args.width, height=args.height,
                              camera=args.camera, light=args.light, device=args.device, pixel_samples=args.pixel_samples,
                              render_settings=args.render_settings, instancing=args.instancing, progress=_FrameProgress(),
                              subdiv_level=args.subdiv_level, **params)
    first = seq.frames[0]
    rs = seq.render_settings
    out, why = output_of(types.SimpleNamespace(render_settings=rs, path=first.stats["scene"]["path"]), args.out,
                         _default_output(scene_file, args.technique))
    for w in seq.warnings + sorted({w for fr in seq.frames for w in fr.stats["warnings"]}):
        print(f"warning: {w}", file=sys.stderr)
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
          f"{sum(ms) / len(ms):.1f} ms a frame (min {min(ms):.1f}, max {max(ms):.1f}); {_sequence_line(seq)}")
    written = [frame_path(out, seq.times[0])] + ([frame_path(out, seq.times[-1])] if len(seq.times) > 1 else [])
    print(f"wrote {' ... '.join(written)}{why}" + (f", PNGs {frame_path(args.png, seq.times[0])} ..." if args.png else "")
          + (f", {args.stats} and a JSON per frame" if args.stats else ""))
    return 0


def _compile_note(ms: float) -> str:
    """`` (+ N ms compiling/loading kernels, not counted)`` when Warp compiled or loaded modules."""
    return f" (+ {ms:.1f} ms compiling/loading kernels, not counted)" if ms >= 0.05 else ""


def cmd_plan(args) -> int:
    techs = args.technique or None
    scene_file = _check_args(args, techs or [])
    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level)
    auto = _auto_args(args, "auto" if techs and "auto" in techs else None)
    p = wsoft.plan(scene, techs, light=args.light, camera=args.camera, auto=auto or None)
    if args.json:
        print(json.dumps(p, indent=2))
        return 0
    print(f"scene {p['scene']}: {p['triangles']} triangles, up {p['up_axis']}, {p['meters_per_unit']:g} m/unit"
          + (f", time code {p['time']:g}" if p["time"] is not None else ""))
    fr = p["framing"]
    print(f"render settings: {fr['render_settings']} (from {fr['render_settings_source']})" if fr["render_settings"] else
          "render settings: none (no --render-settings, no renderSettingsPrimPath metadata, none from GetStageRenderSettings)")
    print(f"camera: {fr['camera']} (from {fr['camera_source']}); {fr['resolution'][0]}x{fr['resolution'][1]} "
          f"(from {fr['resolution_source']}), pixel aspect {fr['pixel_aspect']:g}, {fr['conform_policy']}"
          + (f", data window {fr['data_window']}" if fr["data_window"] else ""))
    if fr["product"]:
        print(f"render product: {fr['product']}: V as {fr['visibility_var']!r}" + (f", default output {fr['product_name']}" if fr["product_name"] else ""))
    print(f"purposes loaded: {', '.join(p['purposes']) or '(none)'}")
    inst = p["instancing"]
    if inst["mode"] == "none":
        print("instancing: none (no instances kept: the stage has none, or it was flattened)")
    else:
        print(f"instancing: kept, {inst['instances']:,} instances of {inst['prototypes']} prototypes "
              f"({inst['prototype_triangles']:,} prototype triangles placed as {inst['instanced_triangles']:,}; "
              f"{inst['soup_triangles']:,} triangles not instanced)")
    for name, why in p.get("flattened_for", {}).items():
        print(f"{name}: renders the stage flattened ({why})")
    print("shadow-casting lights:" + ("" if p["lights"] else " (none)"))
    for l in p["lights"]:
        print(f"  {l['path']:<32} {l['kind']:<8} {l['size']}")
        em = l["emits"]
        toward = f"({', '.join(f'{c:.3g}' for c in em['direction'])})" if "direction" in em else ""
        if em["side"] == "front":
            print(f"      emits: from its front only, toward {toward}; {em['points_behind']} of {em['points']} mesh points lie behind "
                  f"its plane" + (" (they get none of its light: V = 0)" if em["points_behind"] else ""))
        else:
            print(f"      emits: {em['side']}" + (f" {toward}" if toward else ""))
        sh = l["shadow"]
        lk = sh["link"]
        print(f"      collection:shadowLink: {lk['excluded_prims']} of {lk['prims']} prims excluded"
              + (f" ({', '.join(lk['excluded'])}{', ...' if lk['excluded_prims'] > len(lk['excluded']) else ''}): {lk['applied']}" if lk["excluded_prims"] else ""))
        dist = "unlimited" if sh["distance"] is None else f"{sh['distance']:g} scene units: {sh['distance_applied']}"
        print(f"      shadow:distance: {dist}")
        print(f"      shadow:color: ({', '.join(f'{c:g}' for c in sh['color'])}): {sh['color_applied']}")
        print(f"      shadow:falloff: {sh['falloff']:g}, falloffGamma {sh['falloff_gamma']:g}: {sh['falloff_applied']}")
        if l["path"] in p.get("light_views", {}):
            print(f"      light views (shadow-map techniques, cube=auto): {p['light_views'][l['path']]}")
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
    for n in p["notes"]:
        print(f"note: {n}")
    for name, passes in p["techniques"].items():
        print(f"{name}: {' -> '.join(passes)}")
    for name, why in p["not_applicable"].items():
        for w in why:
            print(f"{name}: not applicable to {w['light']}: {w['reason']}")
    for name, models in p.get("cylinder_lights", {}).items():
        for m in models:
            print(f"{name}: cylinder light {m['light']}: {m['model']}")
    for light, a in p.get("auto", {}).items():
        print_auto_plan(light, a)
    return 0


def print_auto_plan(light: str, a: dict) -> None:
    """``wsoft plan --technique auto``: a light's features, every candidate's predictions, the choice and the runner-up."""
    print(_auto_line(light, a))
    m = a["model"]
    print(f"  model: {m['path']} ({m.get('predicts', 'frame model')}; {m['device_kind']}; "
          + ", ".join(f"{q} by {v}" for q, v in m["method"].items())
          + (f"; times x {m['scale']:.3g}" if m["scale"] != 1.0 else "") + ")" + (f"; {m['note']}" if m["note"] else ""))
    print("  features: " + ", ".join(f"{k} {v:.4g}" for k, v in a["features"].items()))
    if a["warning"]:
        print(f"  warning: {a['warning']}")
    for t, why in a.get("not_candidates", {}).items():
        print(f"  {t}: {why}")
    num = lambda v, w: f"{v:>{w}.4f}" if v is not None else f"{'-':>{w}}"  # noqa: E731
    print(f"  {'candidate':<52} {'pred. ms':>9} {'ms bound':>9} {'pred. error':>11} {'error bound':>11} {'pred. ꟻLIP':>10} {'ꟻLIP bound':>10} "
          f"{'pred. flicker':>13} {'flicker bound':>13}")
    for c in a["candidates"]:
        mark = " <- choice" if c["setting"] == a["choice"]["setting"] else " <- runner-up" if a["runner_up"] and c["setting"] == a["runner_up"]["setting"] else ""
        print(f"  {c['setting']:<52} {c['predicted_ms']:>9.1f} {c['ms_bound']:>9.1f} {num(c.get('predicted_error'), 11)} {num(c.get('error_bound'), 11)} "
              f"{num(c.get('predicted_flip'), 10)} {num(c.get('flip_bound'), 10)} {num(c.get('predicted_flicker'), 13)} {num(c.get('flicker_bound'), 13)}{mark}")


def cmd_techniques(args) -> int:
    from wsoft.techniques import TECHNIQUES, markdown_table

    if args.markdown:
        print(markdown_table())
        return 0
    desc = [TECHNIQUES[n].describe() for n in sorted(TECHNIQUES)]
    if args.json:
        print(json.dumps(desc, indent=2, default=str))
        return 0
    for d in desc:
        print(f"{d['name']}: {d['summary']}")
        print(f"  reads: {', '.join(d['reads'])}; writes: {', '.join(d['writes'])}")
        for spec in TECHNIQUES[d["name"]].passes:
            print(f"  pass {spec.text()}")
        for p in d["parameters"]:
            rng = f" [{p['range']}]" if p["range"] else ""
            print(f"  {p['name']:<16} {p['type']:<6} default {p['default']!s:<8} {p['meaning']}{rng}")
        for q in d["quality"]:
            print(f"  quality: {q['param']} over {', '.join(map(str, q['values']))} ({q['note']})")
        if d["cylinder_light"]:
            print(f"  cylinder light: {d['cylinder_light']}")
    return 0


def _technique_sets(names: list[str], sets: list[str] | None) -> list[tuple[str, dict]]:
    """``-t`` names with their ``--set`` values: ``name.key=value`` for one of them, ``key=value``
    for the only one."""
    from wsoft.errors import ParameterError

    params: dict[str, dict] = {n: {} for n in names}
    for k, v in _parse_sets(sets).items():
        if "." in k and k.split(".", 1)[0] in params:
            t, key = k.split(".", 1)
            params[t][key] = v
        elif len(names) == 1:
            params[names[0]][k] = v
        else:
            raise ParameterError(f"--set {k}={v}: with several techniques write TECHNIQUE.{k}={v}")
    return [(n, params[n]) for n in names]


def _short_table(frames, reference: str | None) -> list[str]:
    """Markdown rows: each technique's frame ms, MAE and penumbra MAE (its first light), the reference first."""
    rows = ["| technique | frame ms | MAE | penumbra MAE |", "|---|---:|---:|---:|"]
    for label in sorted(frames, key=lambda l: l != reference):
        st = frames[label].stats
        e = st.get("error")
        rows.append(f"| {label} | {st['timings_ms']['total']:.1f} | " + (f"{e['mae']:.4f} | {e['mae_penumbra']:.4f} |" if e else "- | - |"))
    return rows


def cmd_compare(args) -> int:
    """Render techniques and the reference in one graph; write EXR/PNG of each, each technique's ꟻLIP
    map (magma), one grid image of them all beside the reference and a time / error table."""
    check_output(args.out_dir, "--out-dir", folder=True)
    names = list(dict.fromkeys(args.technique or ["hard"]))
    scene_file = _check_args(args, names)
    techs = _technique_sets(names, args.set)
    auto = _auto_args(args, "auto" if "auto" in names else None)
    techs = [(n, {**p, **auto}) if n == "auto" else (n, p) for n, p in techs]
    if args.frames is not None:
        return _compare_frames(args, techs, scene_file)
    import wsoft
    from wsoft.io import write_gray_png
    from wsoft.metrics.figures import write_compare_grid
    from wsoft.metrics.flip import write_flip_png
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level)
    with CompileNotice(args.device, None if "auto" in names else names + ["reference"]), PassProgress("compare") as progress:
        fs = wsoft.compare(scene, techs, samples=args.samples, width=args.width, height=args.height, camera=args.camera, light=args.light,
                           device=args.device, progress=progress)
    for light, c in fs["auto"].stats["counters"]["techniques"].get("auto", {}).items() if "auto" in fs else ():
        print(_auto_line(light, c["auto"]))
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
             f"`{os.path.basename(grid)}`: each technique's shaded image and its V minus the reference's (red: lighter, blue: darker)"
             + (", for its first light; every light's errors are below." if several else "."), "",
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
    for w in sorted({w for fr in fs.values() for w in fr.stats["warnings"]}):
        print(f"warning: {w}", file=sys.stderr)
    print_notes(n for fr in fs.values() for n in fr.stats["notes"])
    print(f"\nwrote {', '.join(written)}, {grid}, {md}")
    return 0


def _compare_frames(args, techs, scene_file: str) -> int:
    """``compare --frames``: per time code each technique's EXR/PNG/JSON (``<stage>-<label>.0012.exr``),
    ``<stage>-compare.md`` / ``<stage>-sequence.json`` with the temporal measures (flicker against
    the reference, mean and worst error) and each frame's times and errors, and ``<stage>-compare.png``,
    the first frame's grid (:func:`wsoft.metrics.figures.write_compare_grid`)."""
    from wsoft.metrics.figures import write_compare_grid
    from wsoft.metrics.sequences import compare_sequence
    from wsoft.pipeline.sequence import frame_path

    _frames_args(args)
    with CompileNotice(args.device, [n for n, _ in techs] + ["reference"]):
        seq = compare_sequence(scene_file, techs, frames=args.frames, samples=args.samples, width=args.width, height=args.height,
                               camera=args.camera, light=args.light, device=args.device, render_settings=args.render_settings,
                               instancing=args.instancing, progress=_FrameProgress(), subdiv_level=args.subdiv_level)
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
             "(red: lighter, blue: darker).", "", f"Scene: {_sequence_line(seq)}.", "", "## Per frame", "", *per_frame]
    md = os.path.join(args.out_dir, f"{stem}-compare.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    js = os.path.join(args.out_dir, f"{stem}-sequence.json")
    with open(js, "w") as f:
        json.dump({"times": seq.times, "summary": seq.summary, "frames": seq.stats, "warnings": seq.warnings}, f, indent=2, default=str)
    print("\n".join(lines))
    for w in seq.warnings + sorted({w for fs in seq.frames for fr in fs.values() for w in fr.stats["warnings"]}):
        print(f"warning: {w}", file=sys.stderr)
    print_notes(n for fs in seq.frames for fr in fs.values() for n in fr.stats["notes"])
    print(f"\nwrote {len(seq.times)} frames of {', '.join(labels)} ({stem}-<technique>{frame_path('', seq.times[0])}.exr/.png/.json ...), "
          f"{grid}, {md}, {js}")
    return 0


def cmd_bake(args) -> int:
    """Bake a technique's visibility into a layer of overs (primvars, optional textures)."""
    from wsoft.errors import ParameterError
    from wsoft.params import parse_frames

    check_output(args.out, "--out")
    if not args.out.endswith((".usda", ".usdc", ".usd")):
        raise ParameterError(f"--out {args.out}: the layer must be a .usda, .usdc or .usd file")
    frames = None
    if args.frames is not None:
        try:
            frames = parse_frames(args.frames)
        except ValueError as exc:
            raise ParameterError(f"--frames {exc}") from None
    if args.texture_size is not None and not 1 <= args.texture_size <= 8192:
        raise ParameterError(f"--texture-size {args.texture_size} out of range [1, 8192]")
    if args.texture_dir:
        check_output(args.texture_dir, "--texture-dir", folder=True)
    if not 0.0 <= args.crease_angle <= 180.0:
        raise ParameterError(f"--crease-angle {args.crease_angle:g} out of range [0, 180]")
    scene_file = _check_args(args, [args.technique])
    import wsoft

    params = _parse_sets(args.set)
    stats: dict = {}
    t0 = time.perf_counter()

    def progress(done, total, t):
        if total > 1:
            f = stats["frames"][-1]
            print(f"frame {t:g} ({done}/{total}): {f['total_ms'] / 1e3:.2f} s", file=sys.stderr)

    with CompileNotice(args.device, [args.technique]):
        wsoft.bake(scene_file, args.technique, light=args.light, frames=frames, out=args.out, texture_size=args.texture_size,
                   texture_dir=args.texture_dir, device=args.device, crease_angle=args.crease_angle, stats=stats, progress=progress,
                   subdiv_level=args.subdiv_level, **params)
    wall = time.perf_counter() - t0
    for w in stats["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    print_notes(stats["notes"])
    fr = stats["frames"]
    per = sum(f["total_ms"] for f in fr) / len(fr) / 1e3
    comp = sum(f["compile_ms"] for f in fr)
    kinds = {}
    for m in stats["meshes"].values():
        kinds[m["interpolation"]] = kinds.get(m["interpolation"], 0) + 1
    print(f"{args.technique} on {os.path.basename(scene_file)}: {len(stats['meshes'])} meshes "
          f"({', '.join(f'{n} {k}' for k, n in sorted(kinds.items()))}), {fr[0]['points']} points, lights "
          f"{', '.join(stats['lights'].values())}, {len(fr)} frame(s): {per:.2f} s per frame{_compile_note(comp)}; {wall:.1f} s in all")
    print(f"wrote {args.out}" + (f" and {len(stats['textures'])} texture(s)" if stats["textures"] else ""))
    return 0


def _sweeps() -> dict:
    """The harness's sweeps (:data:`wsoft.bench.harness.SWEEPS`)."""
    from wsoft.bench.harness import SWEEPS

    return SWEEPS


def cmd_calibrate(args) -> int:
    from wsoft.auto.calibrate import calibrate
    from wsoft.errors import ParameterError
    from wsoft.parallel import resolve_device

    if args.quick and args.rows:
        raise ParameterError("calibrate: --quick or --rows, one of the two")
    if args.quick and (args.temporal or args.modern):
        raise ParameterError("calibrate: --temporal and --modern go with --rows, not --quick")
    for path, what in ((args.rows, "--rows"), (args.features, "--features"), (args.temporal, "--temporal"), (args.modern, "--modern")):
        if path and not os.path.isfile(path):
            raise ParameterError(f"{what} {path}: no such file")
    check_device(args.device)
    if args.out:
        check_output(args.out, "--out")
    dest, what = calibrate(rows=args.rows, features=args.features, quick=args.quick, device=resolve_device(args.device), out=args.out,
                           temporal=args.temporal, modern=args.modern)
    print(f"wrote {dest}: {what}")
    return 0


def cmd_bench(args) -> int:
    from wsoft.bench.harness import run_sweep, sweep_name

    _sweeps()

    name = sweep_name(args.sweep)
    for d in args.device or []:
        check_device(d)
    check_output(args.out_dir, "--out-dir", folder=True)
    from wsoft.bench.dist import parse_resources

    dist = dict(workers=args.workers, scheduler=args.scheduler, resources=parse_resources(args.resources),
                threads_per_worker=args.threads_per_worker, cache_dir=args.cache_dir)
    with CompileNotice((args.device or [None])[0]):
        return run_sweep(name, quick=args.quick, device=args.device, out_dir=args.out_dir, fresh=args.fresh, scenes=args.scenes, **dist)


def _light_kinds(lights: list) -> str:
    """``[[name, kind], ...]`` as ``rect, 2 sphere``: each kind once, in order, with its count."""
    counts: dict[str, int] = {}
    for _, kind in lights:
        counts[kind] = counts.get(kind, 0) + 1
    return ", ".join(k if n == 1 else f"{n} {k}" for k, n in counts.items()) or "-"


def cmd_scenes(args) -> int:
    """The bundled stages: name, triangles, shadow-casting lights, frames and what each shows, from
    ``wsoft.usd_scenes.ABOUT`` and its catalog (a stage missing from the catalog is read)."""
    from wsoft import usd_scenes

    cat = usd_scenes.catalog()
    missing = [n for n in usd_scenes.names() if n not in cat]
    if missing:  # stages added since the catalog was written: read them
        from wsoft.scene.catalog import measure

        cat = {**cat, **{n: measure(n) for n in missing}}
    entries = {n: {**cat[n], "about": usd_scenes.ABOUT.get(n, "")} for n in usd_scenes.names()}
    if args.json:
        print(json.dumps(entries, indent=2))
        return 0
    lights = {n: _light_kinds(e["lights"]) for n, e in entries.items()}
    w, lw = max(map(len, entries)), max(map(len, lights.values()))
    print(f"{'name':<{w}}  {'triangles':>10}  {'lights':<{lw}}  {'frames':<6}  what it shows")
    for n, e in entries.items():
        frames = f"{e['frames'][0]:g}-{e['frames'][1]:g}" if e["frames"] else ""
        print(f"{n:<{w}}  {e['triangles']:>10,}  {lights[n]:<{lw}}  {frames:<6}  {e['about']}")
    print(f"\nA name works wherever a stage file does (wsoft render box_plane -t pcss); the files are in {usd_scenes.folder()}.")
    return 0


def _modules(n: int) -> str:
    return f"{n} module{'' if n == 1 else 's'} compiled"


def cmd_warmup(args) -> int:
    """Compile into Warp's kernel cache, once per device, the kernels of every technique (a tiny
    render of each on ``box_plane``, default parameters), of the metric passes (a comparison) and
    every other kernel module wsoft defines; with ``--technique``, those techniques' only. Prints
    each technique's time and the total."""
    devices = args.device or ["cpu", None]
    for d in devices:
        check_device(d)
    from wsoft.techniques import check_names

    check_names(args.technique or [])
    import warp as wp

    import wsoft
    from wsoft.errors import WsoftError
    from wsoft.parallel import on_compile, resolve_device, uncached_modules
    from wsoft.techniques import TECHNIQUES

    scene = wsoft.load_scene("box_plane")
    compiled: list[str] = []
    remove = on_compile(lambda module, device: compiled.append(module))
    try:
        for dev in dict.fromkeys(resolve_device(d) for d in devices):
            t0, n0 = time.perf_counter(), len(compiled)
            print(f"{dev} (kernel cache {wp.config.kernel_cache_dir}):", flush=True)
            for name in args.technique or TECHNIQUES:
                t, n = time.perf_counter(), len(compiled)
                try:
                    wsoft.render(scene, name, width=16, height=12, device=dev)
                except WsoftError as exc:
                    print(f"  {name}: not compiled ({exc.line()})")
                    continue
                print(f"  {name}: {time.perf_counter() - t:.1f} s, {_modules(len(compiled) - n)}", flush=True)
            if not args.technique:
                t, n = time.perf_counter(), len(compiled)
                wsoft.compare(scene, ["hard"], samples=4, width=16, height=12, device=dev)
                for module in uncached_modules(dev):
                    wp.load_module(module, device=dev)
                print(f"  metric passes and the other modules: {time.perf_counter() - t:.1f} s, {_modules(len(compiled) - n)}")
            print(f"{dev}: {_modules(len(compiled) - n0)} in {time.perf_counter() - t0:.1f} s")
    finally:
        remove()
    return 0


def _version() -> str:
    """The installed package's version (``importlib.metadata``), else the source's ``wsoft.__version__``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("wsoft")
    except PackageNotFoundError:  # run from a source tree that is not installed
        from wsoft import __version__

        return __version__


_INST_HELP = ("PointInstancers and instanceable prims: keep them instanced (prototypes once), flatten them, or auto "
              "(default: keep them when they place more than 4M triangles)")
_SCENE_HELP = "a .usda/.usdc/.usdz file or a bundled stage's name (box_plane; `wsoft scenes` lists them)"


def _rs_help(overrides: str) -> str:
    return ("RenderSettings prim to use (default: the stage metadata renderSettingsPrimPath, else "
            f"UsdRender.Settings.GetStageRenderSettings, else none); {overrides}")


_RS_HELP = _rs_help("--width/--height/--camera override its values")
_DEVICE_HELP = "cpu or cuda:N (default: cuda:0 when available, else cpu)"
_TIME_HELP = "USD time code (default: the stage's start time code; without a time range, its earliest time sample)"


_SUBDIV_HELP = ("refine subdivision surfaces (subdivisionScheme catmullClark, loop or bilinear; unauthored means catmullClark) "
                "N times, 1 to 4, each level with 4x the faces (default: 0, their control cages)")


def subdiv_option(parser) -> None:
    """``--subdiv-level N``: how many times the stage's subdivision surfaces are refined
    (:func:`wsoft.load_scene`'s ``subdiv_level``; render, compare, plan and bake)."""
    parser.add_argument("--subdiv-level", type=int, default=0, metavar="N", help=_SUBDIV_HELP)


def print_notes(notes) -> None:
    """The load's notes (``Scene.notes``: no problem, worth knowing), once each, ``note: ...`` on stderr."""
    for n in dict.fromkeys(notes):
        print(f"note: {n}", file=sys.stderr)


def _one_line_warnings() -> None:
    """wsoft's own warnings (a technique plugin left out, non-finite values) print as one line,
    ``warning: ...``; other warnings keep Python's format."""
    import warnings

    if getattr(warnings.showwarning, "_wsoft", False):
        return
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if category.__module__.startswith("wsoft."):
            print(f"warning: {message}", file=file or sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)

    show._wsoft = True
    warnings.showwarning = show


def auto_options(p) -> None:
    """``--technique auto``'s options: a time budget or an error target, and the model file."""
    p.add_argument("--budget-ms", type=float, metavar="MS", help="with --technique auto: per light, the lowest predicted error whose "
                   "predicted time fits MS (split evenly between the lights)")
    p.add_argument("--target-error", type=float, metavar="MAE", help="with --technique auto: per light, the fastest setting predicted "
                   "to reach penumbra MAE")
    p.add_argument("--target-flip", type=float, metavar="FLIP", help="with --technique auto: per light, the fastest setting predicted "
                   "to reach mean ꟻLIP FLIP")
    p.add_argument("--target-flicker", type=float, metavar="F", help="with --technique auto: per light, the fastest setting with flicker "
                   "rows (wsoft bench temporal) predicted to flicker by at most F over a sequence")
    p.add_argument("--auto-model", metavar="JSON", help="with --technique auto: the model file (default: the package's for the device "
                   "kind; see wsoft calibrate)")


def parser() -> argparse.ArgumentParser:
    """The command line's parser (every subcommand; Warp and USD not imported)."""
    SWEEPS = _sweeps()
    from wsoft.techniques import NAMES  # the names only: the technique modules import Warp

    techniques = sorted(NAMES)
    one_of = "one of: " + ", ".join(techniques) + ", or auto (with --budget-ms or --target-error)"
    fmt = _Help
    ap = argparse.ArgumentParser(prog="wsoft", description="Soft-shadow techniques in Warp on USD stages.",
                                 epilog="first steps: wsoft scenes; wsoft compare box_plane -t pcss -t hard (into out/); "
                                 "wsoft warmup (compiles every kernel once)")
    ap.add_argument("--version", action="version", version=f"wsoft {_version()}")
    sub = ap.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("render", help="render a stage with a technique, write EXR or PNG (and a shaded PNG, stats)", formatter_class=fmt)
    r.add_argument("scene", help=_SCENE_HELP)
    r.add_argument("--technique", "-t", required=True, metavar="TECHNIQUE", help=one_of)
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="technique parameter (repeatable)")
    auto_options(r)
    r.add_argument("--width", type=int, help="image width in pixels (default: 640, or the render settings' resolution; "
                   "--width alone keeps their aspect)")
    r.add_argument("--height", type=int, help="image height in pixels (default: 480, or the render settings' resolution)")
    r.add_argument("--camera", help="camera prim path (default: the render settings' camera, else the stage's first camera, else automatic)")
    r.add_argument("--render-settings", metavar="PRIM", help=_RS_HELP)
    r.add_argument("--light", help="light path or name for V (default: every shadow-casting light; V = the first)")
    r.add_argument("--instancing", choices=("auto", "keep", "flatten"), default="auto", help=_INST_HELP)
    r.add_argument("--time", type=float, help=_TIME_HELP)
    r.add_argument("--frames", metavar="A:B[:STEP]", help="a sequence: every time code from A to B (step 1, or STEP) within the stage's "
                   "range, one output per frame named out.0012.exr; --stats gets the sequence's summary")
    r.add_argument("--device", help=_DEVICE_HELP)
    r.add_argument("--pixel-samples", type=int, default=1, help="G-buffer samples per pixel")
    r.add_argument("--out", help="output file, by its extension: .exr (every channel, float32) or .png (V as 16-bit linear grey) "
                   "(default: the productName of the render settings' product with a visibility RenderVar, else "
                   "<stage>-<technique>.exr in the current folder)")
    r.add_argument("--stats", help="stats JSON")
    r.add_argument("--png", help="shaded PNG (R G B, sRGB)")
    subdiv_option(r)
    r.set_defaults(fn=cmd_render)

    c = sub.add_parser("compare", help="render techniques and the reference in one graph; EXR/PNG of each, a grid image, a time and error table",
                       formatter_class=fmt, description="Writes OUT_DIR/<stage>-<technique>.exr/.png/-V.png/.json per technique, "
                       "<stage>-<technique>-flip.png (its ꟻLIP map against the reference, magma) per technique compared, "
                       "OUT_DIR/<stage>-compare.png (every technique's shaded image and its difference from the reference's V, "
                       "titled with its parameters, frame ms and penumbra MAE) "
                       "and OUT_DIR/<stage>-compare.md (times and errors against the reference: MAE of V, ꟻLIP of the shaded image).")
    c.add_argument("scene", help=_SCENE_HELP)
    c.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE", help="a technique (repeatable; default: hard); " + one_of)
    auto_options(c)
    c.add_argument("--set", action="append", metavar="[TECHNIQUE.]KEY=VALUE", help="a parameter (TECHNIQUE.KEY with several techniques)")
    c.add_argument("--samples", type=int, default=256, help="reference light samples per pixel")
    c.add_argument("--width", type=int, help="image width in pixels (default: 640, or the render settings' resolution)")
    c.add_argument("--height", type=int, help="image height in pixels (default: 480, or the render settings' resolution)")
    c.add_argument("--camera", help="camera prim path (default: the render settings' camera, else the stage's first camera, else automatic)")
    c.add_argument("--render-settings", metavar="PRIM", help=_RS_HELP)
    c.add_argument("--light", help="light path or name whose V is compared (default: every shadow-casting light)")
    c.add_argument("--instancing", choices=("auto", "keep", "flatten"), default="auto", help=_INST_HELP)
    c.add_argument("--time", type=float, help=_TIME_HELP)
    c.add_argument("--frames", metavar="A:B[:STEP]", help="a sequence: every time code from A to B (step 1, or STEP) within the stage's "
                   "range; adds flicker against the reference and each frame's error (<stage>-compare.md, <stage>-sequence.json)")
    c.add_argument("--device", help=_DEVICE_HELP)
    c.add_argument("--out-dir", default="out", help="where the images, stats and the compare table are written")
    subdiv_option(c)
    c.set_defaults(fn=cmd_compare)

    p = sub.add_parser("plan", help="lights, cutouts and the passes each technique would run", formatter_class=fmt)
    p.add_argument("scene", help=_SCENE_HELP)
    p.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE",
                   help="a technique whose passes to list (repeatable; default: all); " + one_of)
    p.add_argument("--light", help="light path or name (default: every shadow-casting light)")
    p.add_argument("--camera", help="camera prim path (default: the render settings' camera, else the stage's first camera, else automatic)")
    p.add_argument("--render-settings", metavar="PRIM", help=_rs_help("--camera overrides its camera"))
    p.add_argument("--instancing", choices=("auto", "keep", "flatten"), default="auto", help=_INST_HELP)
    p.add_argument("--time", type=float, help=_TIME_HELP)
    p.add_argument("--json", action="store_true", help="the plan as JSON")
    auto_options(p)
    subdiv_option(p)
    p.set_defaults(fn=cmd_plan)

    t = sub.add_parser("techniques", help="techniques and their parameters", formatter_class=fmt)
    t.add_argument("--json", action="store_true", help="every technique's description as JSON")
    t.add_argument("--markdown", action="store_true", help="the README's technique table")
    t.set_defaults(fn=cmd_techniques)

    s = sub.add_parser("scenes", help="the bundled stages: triangles, lights, frames and what each shows", formatter_class=fmt)
    s.add_argument("--json", action="store_true", help="the list as JSON")
    s.set_defaults(fn=cmd_scenes)

    k = sub.add_parser("bake", help="bake a technique's visibility into a USD layer of overs (primvars, optional textures)",
                       formatter_class=fmt, description="Writes OUT, a layer to add as a sublayer of the stage: on every mesh a float "
                       "primvar primvars:wsoft:visibility:<light> (vertex, or faceVarying on meshes with creases), time-sampled over "
                       "--frames, computed at the vertices themselves (seen by a camera or not); with --texture-size, an EXR per mesh "
                       "and light over its st and a UsdUVTexture hookup under <mesh>/wsoftVisibility.")
    k.add_argument("scene", help="a .usda/.usdc/.usdz file or a bundled stage's name (lightmapped_bridge)")
    k.add_argument("--technique", "-t", required=True, metavar="TECHNIQUE", help=one_of + " (izb with --set aa=none; ssm without a budget_map)")
    k.add_argument("--set", action="append", metavar="KEY=VALUE", help="technique parameter (repeatable)")
    k.add_argument("--light", help="light path or name (default: every shadow-casting light the technique supports)")
    k.add_argument("--frames", metavar="A:B[:STEP]", help="time codes A to B inclusive (step 1, or STEP), or one time code A, within the "
                   "stage's range: time samples (default: the time render uses, written as default values)")
    k.add_argument("--out", required=True, help="the layer to write (.usda, .usdc or .usd)")
    k.add_argument("--texture-size", type=int, metavar="N", help="also bake an N x N texture per mesh with st and light")
    k.add_argument("--texture-dir", help="where the textures go (default: the layer's folder)")
    k.add_argument("--crease-angle", type=float, default=30.0, help="degrees: faces around a vertex closer than this share its "
                   "normal; farther ones make the mesh faceVarying")
    k.add_argument("--device", help=_DEVICE_HELP)
    subdiv_option(k)
    k.set_defaults(fn=cmd_bake)

    b = sub.add_parser("bench", help="run a benchmark sweep; rows go to <out-dir>/<sweep>.jsonl", formatter_class=fmt)
    b.add_argument("sweep", help="one of: " + ", ".join(sorted(SWEEPS)))
    b.add_argument("--quick", action="store_true", help="the CI-sized version")
    b.add_argument("--device", action="append", help="device(s) to sweep (default: the default device)")
    b.add_argument("--out-dir", default="reports", help="where rows, reports and images go (default: ./reports)")
    b.add_argument("--scenes", help="folder of the scenes (default: the stages installed with wsoft)")
    b.add_argument("--fresh", action="store_true", help="discard earlier rows instead of resuming")
    b.add_argument("--workers", type=int, metavar="N", help="run the rows on an embedded Dask cluster of N worker processes "
                   "(needs wsoft[dist]; the first worker alone times, the others compute references)")
    b.add_argument("--scheduler", metavar="ADDRESS", help="run the rows on a running Dask cluster (tcp://HOST:8786); its workers that "
                   "may time declare --resources MACHINE=1 (GPU=1 for CUDA)")
    b.add_argument("--resources", metavar="NAME=N[,...]", help="what every embedded worker declares (MACHINE=1: each times on its own; "
                   "default: the first worker holds MACHINE=1,GPU=1)")
    b.add_argument("--threads-per-worker", type=int, default=1, metavar="N", help="Dask threads of each embedded worker (default 1)")
    b.add_argument("--cache-dir", metavar="DIR", help="the references' cache, a folder every worker sees (default: $WSOFT_CACHE_DIR, "
                   "else ~/.cache/wsoft)")
    b.set_defaults(fn=cmd_bench)

    k = sub.add_parser("calibrate", help="rebuild --technique auto's model from your own sweep rows, or scale it by a quick measurement",
                       formatter_class=fmt, description="From sweep rows (--rows: wsoft bench pareto's on this machine; their features "
                       "computed, or read from --features, wsoft bench auto's rows): both predictors compared scene by scene held out, "
                       "each quantity by the closer, fitted to every frame. --quick: no sweep, the model's times scaled by measured "
                       "over predicted times of a few settings on a small bundled frame.")
    k.add_argument("--rows", metavar="JSONL", help="a pareto sweep's rows (reports/pareto.jsonl)")
    k.add_argument("--features", metavar="JSONL", help="their features (reports/auto.jsonl; those it lacks are computed)")
    k.add_argument("--temporal", metavar="JSONL", help="wsoft bench temporal's rows (reports/temporal.jsonl): the flicker model")
    k.add_argument("--modern", metavar="JSONL", help="wsoft bench modern's rows (reports/modern.jsonl): entries the pareto row of the same "
                   "frame lacks are added")
    k.add_argument("--quick", action="store_true", help="scale the model's times by a quick measurement instead")
    k.add_argument("--device", help="the device to calibrate for (default: the default device)")
    k.add_argument("--out", metavar="JSON", help="where to write the model (default: the package's model of the device kind)")
    k.set_defaults(fn=cmd_calibrate)

    w = sub.add_parser("warmup", help="compile every technique's kernels once (Warp's kernel cache), so later runs start at once",
                       formatter_class=fmt)
    w.add_argument("--device", action="append", help="a device to compile for (repeatable; default: cpu and the default device, "
                   "cuda:0 when available)")
    w.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE",
                   help="compile this technique's kernels only (repeatable; default: every technique, the metric passes and "
                   "every other kernel module); " + one_of)
    w.set_defaults(fn=cmd_warmup)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    from wsoft.errors import WsoftError

    _one_line_warnings()

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


def run_captured(argv) -> tuple[int, str, str]:
    """``wsoft ARGV`` in this process with what it prints captured: (exit code, stdout, stderr).
    argparse's own exits (``--help``, a malformed argument and its usage line) give their code."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    return rc, out.getvalue(), err.getvalue()


if __name__ == "__main__":
    sys.exit(main())
