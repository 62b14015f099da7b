"""The bundled USD stages (installed as ``wsoft.usd_scenes``): :func:`path` finds one by name.

The stages are written by :mod:`wsoft.stages.bundled` (``python -m wsoft.stages.bundled``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

EXTENSIONS = (".usda", ".usdc", ".usdz", ".usd")


def folder() -> Path:
    """The folder holding the bundled stages (in a checkout or in site-packages)."""
    return Path(str(resources.files(__name__)))


def names() -> list[str]:
    """The bundled scenes' names (file names without extension)."""
    return sorted(p.stem for p in folder().iterdir() if p.suffix in EXTENSIONS)


def path(name: str) -> Path | None:
    """The file of the bundled scene ``name`` (with or without extension), or None."""
    d = folder()
    for cand in [d / name] + [d / (name + e) for e in EXTENSIONS]:
        if cand.is_file():
            return cand
    return None
