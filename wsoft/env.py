"""The environment settings wsoft reads, each read and checked in one place.

| setting | meaning | unset or empty |
|---|---|---|
| ``WSOFT_THREADS`` | threads for CPU launches, a whole number of at least 1 | the cores this process may use |
| ``WSOFT_WARP_VERBOSE`` | ``1``: Warp's own messages (its per-module compile lines, a missing CUDA driver); ``0``: muted | ``0`` |
| ``WSOFT_CACHE_DIR`` | the folder of wsoft's caches (sweep references, generated stages); created when missing | ``~/.cache/wsoft`` |
| ``WSOFT_SCENES`` | an existing folder where ``wsoft bench`` looks up scenes | the bundled stages |

A malformed value is a :class:`~wsoft.errors.ParameterError` naming the setting, its value and
what it takes (the command line prints it as one line and exits with code 2), never a silent
fallback. :func:`check_environment` checks them all; the command line calls it before any command
runs. Imports neither Warp nor USD.
"""

from __future__ import annotations

import os
from pathlib import Path

from wsoft.errors import ParameterError

SETTINGS = ("WSOFT_THREADS", "WSOFT_WARP_VERBOSE", "WSOFT_CACHE_DIR", "WSOFT_SCENES")


def _get(name: str) -> str | None:
    v = os.environ.get(name)
    return v if v not in (None, "") else None


def _bad(name: str, value: str, takes: str) -> ParameterError:
    return ParameterError(f"environment setting {name}={value!r}: {takes}")


def threads() -> int | None:
    """``WSOFT_THREADS`` as a whole number of at least 1; None when it is not set."""
    v = _get("WSOFT_THREADS")
    if v is None:
        return None
    try:
        n = int(v.strip())
    except ValueError:
        n = None
    if n is None or n < 1:
        raise _bad("WSOFT_THREADS", v, "give the threads for CPU launches as a whole number of at least 1, or unset it to use "
                   "every core this process may use")
    return n


def warp_verbose() -> bool:
    """``WSOFT_WARP_VERBOSE``: ``1`` shows Warp's own messages, ``0`` (or unset) mutes them."""
    v = _get("WSOFT_WARP_VERBOSE")
    if v is None or v.strip() == "0":
        return False
    if v.strip() == "1":
        return True
    raise _bad("WSOFT_WARP_VERBOSE", v, "give 1 to show Warp's own messages or 0 to mute them")


def cache_dir() -> Path:
    """``WSOFT_CACHE_DIR``, else ``~/.cache/wsoft``: the folder of wsoft's caches (not created here)."""
    v = _get("WSOFT_CACHE_DIR")
    if v is None:
        return Path.home() / ".cache" / "wsoft"
    p = Path(v).expanduser()
    if p.exists() and not p.is_dir():
        raise _bad("WSOFT_CACHE_DIR", v, "it is a file; give a folder (it is created when missing), or unset it for ~/.cache/wsoft")
    return p


def scenes_dir() -> Path | None:
    """``WSOFT_SCENES``: an existing folder of scenes; None when it is not set."""
    v = _get("WSOFT_SCENES")
    if v is None:
        return None
    p = Path(v).expanduser()
    if not p.is_dir():
        raise _bad("WSOFT_SCENES", v, f"{'not a folder' if p.exists() else 'no such folder'}; give the folder of the scenes, "
                   "or unset it for the bundled stages")
    return p


def check_environment() -> None:
    """Every setting of :data:`SETTINGS` read once: the first malformed one raises."""
    threads()
    warp_verbose()
    cache_dir()
    scenes_dir()
