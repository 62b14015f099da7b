"""What the commands share: checks made before Warp or USD start (outputs, devices, scene names,
``--set`` values, ``--technique auto``'s goals), the output file of a render, and the lines printed
after one (warnings, notes, compile time, a sequence's summary)."""

from __future__ import annotations

import os
import re
import sys
import time


OUTPUT_FORMATS = {".exr": "every channel, float32", ".png": "V as 16-bit linear grey"}
"""What ``render --out`` (or a render product's ``productName``) writes, by extension."""


def parse_sets(items: list[str] | None, techniques: list[str] | None = None) -> dict[str, str]:
    """``--set KEY=VALUE`` items as a dict. With ``techniques`` (the ``-t`` names), a key
    ``NAME.KEY`` whose NAME is a technique not among them is an error saying so."""
    from wsoft.errors import ParameterError

    out = {}
    for item in items or []:
        if "=" not in item:
            raise ParameterError(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        k = k.strip()
        if techniques is not None and "." in k:
            from wsoft.techniques import NAMES

            name = k.split(".", 1)[0]
            if name not in techniques and name in (*NAMES, "auto", "reference"):
                raise ParameterError(f"--set {k}={v.strip()}: {name} is not among the -t techniques ({', '.join(techniques)}); "
                                     f"add -t {name} to render it too")
        out[k] = v.strip()
    return out


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


def default_output(scene_file: str, technique: str) -> str:
    return f"{os.path.splitext(os.path.basename(scene_file))[0]}-{technique}.exr"


def check_args(args, techniques: list[str]) -> str:
    """What a command can check before Warp or USD starts (the technique names, the device, the
    scene); the stage's file."""
    from wsoft.techniques import check_names

    check_names([t for t in techniques if t != "auto"])  # auto: wsoft.auto chooses among the registered ones
    check_device(getattr(args, "device", None))
    return scene_arg(args.scene)


def auto_args(args, technique) -> dict:
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


def auto_line(light: str, a: dict, lights: int = 1) -> str:
    """``auto (budget 40 ms): Light: pcss(...) (predicted 12.0 ms, error 0.031; runner-up ...)``; a
    budget split between ``lights`` lights reads ``budget 200 ms over 2 lights, 100 ms each``."""
    c, r = a["choice"], a["runner_up"]
    (k, v), = a["goal"].items()
    if k == "budget_ms":
        goal = f"budget {v:g} ms" if lights <= 1 else f"budget {v * lights:g} ms over {lights} lights, {v:g} ms each"
    else:
        goal = f"target {k[len('target_'):]} {v:g}"
    q = "error" if k in ("budget_ms", "target_error") else k[len("target_"):]
    return (f"auto ({goal}): {light}: {c['setting']} (predicted {c['predicted_ms']:.1f} ms, {q} {c['predicted_' + q]:.4f})"
            + (f"; runner-up {r['setting']} ({r['predicted_ms']:.1f} ms, {r['predicted_' + q]:.4f})" if r else "")
            + f"; of {len(a['candidates'])} candidates")


def frames_args(args) -> None:
    """``--frames`` and ``--time`` exclude each other."""
    from wsoft.errors import ParameterError

    if args.time is not None:
        raise ParameterError(f"--time {args.time:g} and --frames {args.frames}: give one of them")


class FrameProgress:
    """One line per finished frame on stderr: ``frame 12 (3/24): 0.21 s``."""

    def __init__(self):
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int, t: float) -> None:
        now = time.perf_counter()
        print(f"frame {t:g} ({done}/{total}): {now - self.t0:.2f} s", file=sys.stderr)
        self.t0 = now


def sequence_line(seq) -> str:
    s = seq.summary
    how = ", ".join(f"{s[k]} {w}" for k, w in (("scene_built", "built"), ("scene_refit", "refit"), ("scene_reused", "reused")) if s[k])
    return (f"{s['frames']} frame(s), time codes {seq.times[0]:g}..{seq.times[-1]:g}; scene on the device: {how} "
            f"(load {s['load_ms'] / 1e3:.2f} s, upload {s['upload_ms']:.0f} ms, refit {s['refit_ms']:.0f} ms in all)")


def compile_note(ms: float) -> str:
    """`` (+ N ms compiling/loading kernels, not counted)`` when Warp compiled or loaded modules."""
    return f" (+ {ms:.1f} ms compiling/loading kernels, not counted)" if ms >= 0.05 else ""


def print_warnings(warnings) -> None:
    """``warning: ...`` on stderr for each of ``warnings``, once each, in order."""
    for w in dict.fromkeys(warnings):
        print(f"warning: {w}", file=sys.stderr)


def print_notes(notes) -> None:
    """The load's notes (``Scene.notes``: no problem, worth knowing), once each, ``note: ...`` on stderr."""
    for n in dict.fromkeys(notes):
        print(f"note: {n}", file=sys.stderr)


def one_line_warnings() -> None:
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


def version() -> str:
    """The installed package's version (``importlib.metadata``), else the source's ``wsoft.__version__``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("wsoft")
    except PackageNotFoundError:  # run from a source tree that is not installed
        from wsoft import __version__

        return __version__
