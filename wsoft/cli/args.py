"""The arguments several commands share, defined once: their flags, types and help.

Every value argparse can check without Warp or USD is checked here, by the argument's type: a
malformed or out-of-range number is a usage error naming its flag (exit 2), before any stage loads.
"""

from __future__ import annotations

import argparse
import math
import re

SCENE_HELP = "a .usda/.usdc/.usdz file or a bundled stage's name (box_plane; `wsoft scenes` lists them)"
INST_HELP = ("PointInstancers and instanceable prims: keep them instanced (prototypes once), flatten them, or auto "
             "(default: keep them when they place more than 4M triangles)")
DEVICE_HELP = "cpu or cuda:N (default: cuda:0 when available, else cpu)"
TIME_HELP = "USD time code (default: the stage's start time code; without a time range, its earliest time sample)"
CAMERA_HELP = "camera prim path (default: the render settings' camera, else the stage's first camera, else automatic)"
SUBDIV_HELP = ("refine subdivision surfaces (subdivisionScheme catmullClark, loop or bilinear; unauthored means catmullClark) "
               "N times, 1 to 4, each level with 4x the faces (default: 0, their control cages)")

MAX_SIDE = 65536  # pixels a side; wsoft.pipeline.framing.check_sizes bounds the product (64 Mi pixels)
MAX_PIXEL_SAMPLES = 64  # wsoft.pipeline.framing.check_sizes


def rs_help(overrides: str) -> str:
    return ("RenderSettings prim to use (default: the stage metadata renderSettingsPrimPath, else "
            f"UsdRender.Settings.GetStageRenderSettings, else none); {overrides}")


class Help(argparse.HelpFormatter):
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


class Parser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line, ``wsoft: error: --width 0 out of range [1, 65536]
    (wsoft render --help lists the options)``, exit code 2, as every other error of the command line."""

    def error(self, message):
        m = re.fullmatch(r"argument ([^:]+): (.*)", message, re.S)
        if m:
            flag, rest = m.group(1).split("/")[0], m.group(2)
            if flag == "cmd":
                message = rest.replace("invalid choice:", "unknown command")
            else:
                message = rest if rest.startswith(flag + " ") else f"{flag}: {rest}"
        self.exit(2, f"wsoft: error: {message} ({self.prog} --help lists the options)\n")


def int_in(flag: str, lo: int, hi: int | None = None):
    """An argparse type for ``flag``: a whole number in ``lo .. hi`` (no upper bound when ``hi`` is None)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} {text!r} is not a whole number") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{flag} {v} out of range " + (f"[{lo}, {hi}]" if hi is not None else f"(at least {lo})"))
        return v

    parse.__name__ = "whole number"  # argparse's fallback message names the type
    return parse


def float_in(flag: str, lo: float = -math.inf, hi: float = math.inf):
    """An argparse type for ``flag``: a finite number in ``lo .. hi``."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} {text!r} is not a number") from None
        if not math.isfinite(v) or not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{flag} {text} out of range [{lo:g}, {hi:g}]")
        return v

    parse.__name__ = "number"
    return parse


def technique_help(names) -> str:
    return "one of: " + ", ".join(sorted(names)) + ", or auto (with --budget-ms or --target-error)"


def scene(p, help: str = SCENE_HELP) -> None:
    p.add_argument("scene", help=help)


def sets(p, metavar: str = "KEY=VALUE", help: str = "technique parameter (repeatable)") -> None:
    p.add_argument("--set", action="append", metavar=metavar, help=help)


def size(p, width_help: str = "image width in pixels (default: 640, or the render settings' resolution)") -> None:
    """``--width`` and ``--height``: whole numbers of pixels, 1 to :data:`MAX_SIDE`."""
    p.add_argument("--width", type=int_in("--width", 1, MAX_SIDE), metavar="PIXELS", help=width_help)
    p.add_argument("--height", type=int_in("--height", 1, MAX_SIDE), metavar="PIXELS",
                   help="image height in pixels (default: 480, or the render settings' resolution)")


def camera(p) -> None:
    p.add_argument("--camera", help=CAMERA_HELP)


def render_settings(p, overrides: str = "--width/--height/--camera override its values") -> None:
    p.add_argument("--render-settings", metavar="PRIM", help=rs_help(overrides))


def light(p, help: str) -> None:
    p.add_argument("--light", help=help)


def instancing(p) -> None:
    p.add_argument("--instancing", choices=("auto", "keep", "flatten"), default="auto", help=INST_HELP)


def time(p) -> None:
    p.add_argument("--time", type=float, help=TIME_HELP)  # a non-finite one: the loader names the stage (wsoft.scene.usd)


def frames(p, help: str) -> None:
    p.add_argument("--frames", metavar="A:B[:STEP]", help=help)


def device(p, help: str = DEVICE_HELP, *, repeat: bool = False) -> None:
    p.add_argument("--device", action="append" if repeat else "store", help=help)


def material_purpose(p) -> None:
    """``--material-purpose full|preview``: the UsdShade purpose material bindings resolve for
    (:func:`wsoft.load_scene`'s ``material_purpose``; render, compare, plan and bake)."""
    p.add_argument("--material-purpose", choices=("full", "preview"), default="full",
                   help="the UsdShade purpose material bindings resolve for: full (final frames; a prim without a full binding "
                   "takes its all-purpose one, as UsdShade resolves it) or preview (default: full; docs/usd.md)")


def subdiv(p) -> None:
    """``--subdiv-level N``: how many times the stage's subdivision surfaces are refined
    (:func:`wsoft.load_scene`'s ``subdiv_level``; render, compare, plan and bake)."""
    p.add_argument("--subdiv-level", type=int, default=0, metavar="N", help=SUBDIV_HELP)  # the loader checks it, naming the stage


def auto_options(p) -> None:
    """``--technique auto``'s options: a time budget or an error target, and the model file."""
    goal = float  # wsoft.auto.model.goal_of checks the value, naming its option
    p.add_argument("--budget-ms", type=goal, metavar="MS", help="with --technique auto: per light, the lowest predicted error whose "
                   "predicted time fits MS (split evenly between the lights)")
    p.add_argument("--target-error", type=goal, metavar="MAE", help="with --technique auto: per light, the fastest setting predicted "
                   "to reach penumbra MAE")
    p.add_argument("--target-flip", type=goal, metavar="FLIP", help="with --technique auto: per light, the fastest setting predicted "
                   "to reach mean ꟻLIP FLIP")
    p.add_argument("--target-flicker", type=goal, metavar="F", help="with --technique auto: per light, the fastest setting with flicker "
                   "rows (wsoft bench temporal) predicted to flicker by at most F over a sequence")
    p.add_argument("--auto-model", metavar="JSON", help="with --technique auto: the model file (default: the package's for the device "
                   "kind; see wsoft calibrate)")
