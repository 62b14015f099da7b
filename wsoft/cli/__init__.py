"""``wsoft`` command line: render, compare, plan, techniques, scenes, bake, bench, regress, report, calibrate, warmup.

One module per command (its ``add_parser`` and ``run``); the arguments several share are defined
once in :mod:`wsoft.cli.args`. Bad input prints one line naming the file and prim (or the flag, or
the environment setting) and exits with code 2. Warp and USD are imported by the commands that need
them, never to parse or check the arguments (``wsoft --help`` and argument errors answer at once: an
unknown technique, scene, sweep or device, a number out of range, an output whose extension names no
format wsoft writes, a malformed ``WSOFT_*`` setting). When Warp is about to compile kernels (a cold
kernel cache), one line on stderr says so with a rough time (:class:`CompileNotice`). A reader that
closes the output early (``wsoft techniques | head``) ends the command quietly.
"""

from __future__ import annotations

import argparse
import os
import sys

from wsoft.cli import bake, bench, calibrate, compare, plan, regress, render, report, scenes, techniques, warmup
from wsoft.cli.args import Help, Parser, technique_help
from wsoft.cli.common import (  # noqa: F401  (the names other modules import from wsoft.cli)
    OUTPUT_FORMATS, check_device, check_output, one_line_warnings, output_format, print_notes, scene_arg, version,
)
from wsoft.cli.progress import CompileNotice, PassProgress  # noqa: F401

COMMANDS = (render, compare, plan, techniques, scenes, bake, bench, regress, report, calibrate, warmup)
"""The commands' modules, in the order ``wsoft --help`` lists them."""

EXIT_PIPE = 141  # 128 + SIGPIPE: what a shell reports for a Unix tool whose reader went away


def parser() -> argparse.ArgumentParser:
    """The command line's parser (every subcommand; Warp and USD not imported)."""
    from wsoft.techniques import NAMES  # the names only: the technique modules import Warp

    one_of = technique_help(NAMES)
    ap = Parser(prog="wsoft", description="Soft-shadow techniques in Warp on USD stages.",
                                 epilog="first steps: wsoft scenes; wsoft compare box_plane -t pcss -t hard (into out/); "
                                 "wsoft warmup (compiles every kernel once)", formatter_class=Help)
    ap.add_argument("--version", action="version", version=f"wsoft {version()}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    for command in COMMANDS:
        command.add_parser(sub, one_of)
    return ap


def _quiet_stdout() -> None:
    """After the reader of stdout went away: point stdout at the null device, so that the flush at
    exit finds nowhere to fail (a stream without a file descriptor is left as it is)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    from wsoft.env import check_environment
    from wsoft.errors import WsoftError

    one_line_warnings()

    try:
        check_environment()
        rc = int(args.fn(args) or 0)
        sys.stdout.flush()  # a reader that went away shows here, not at exit
        return rc
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_PIPE
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
    argparse's own exits (``--help``, a malformed argument: one line, :class:`wsoft.cli.args.Parser`) give their code."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    return rc, out.getvalue(), err.getvalue()
