"""wsoft: real-time soft-shadow techniques in NVIDIA Warp, on scenes from USD stages.

Python API::

    import wsoft
    scene = wsoft.load_scene("usd_scenes/box_plane.usda")
    frame = wsoft.render(scene, "hard", width=640, height=480, shadow_map_size=2048)
    ref = wsoft.render(scene, "reference", width=640, height=480, samples=256)
    frame.write_exr("hard.exr"); print(frame.stats["timings_ms"])

    # several techniques in one frame graph, sharing what they have in common
    frames = wsoft.render(scene, ["pcss", ("essm", {"H": 2.0}), "reference"])
    frames["essm"].V, frames.stats["shared_passes"]

    # and their error against the reference, measured by a metric pass
    result = wsoft.compare(scene, ["pcss", "essm"], samples=256)
    result["pcss"].stats["error"]["mae_penumbra"]

    # visibility baked into USD: a layer of overs with primvars:wsoft:visibility:<light> per mesh
    layer = wsoft.bake("usd_scenes/lightmapped_bridge.usda", "pcss", frames="1:48", out="vis.usda")

The names below Warp or USD (everything but the exceptions) are imported at first use, so that
``import wsoft.cli`` and ``wsoft --help`` do not load Warp and USD. Any other wsoft module imports
:mod:`wsoft.parallel` first (Warp quiet, no adjoint code), as ``import wsoft`` used to.
"""

import importlib
import importlib.abc
import importlib.util
import sys
import threading
import types

from wsoft.errors import ParameterError, SceneError, WsoftError

__version__ = "0.1.0"
__all__ = ["Frame", "FrameSet", "ParameterError", "Scene", "SceneError", "TECHNIQUES", "WsoftError", "bake", "compare", "load_scene", "plan",
           "render"]

# name -> the module that defines it, imported at first use
_LAZY = {
    "Frame": "wsoft.render",
    "FrameSet": "wsoft.render",
    "plan": "wsoft.render",
    "render": "wsoft.render",
    "Scene": "wsoft.scene",
    "load_scene": "wsoft.scene",
    "TECHNIQUES": "wsoft.techniques",
    "compare": "wsoft.metrics",
    "bake": "wsoft.bake",
}

# modules that import neither Warp nor USD: what the command line needs to parse its arguments
_WARP_FREE = frozenset({"wsoft.errors", "wsoft.params", "wsoft.cli", "wsoft.__main__", "wsoft.techniques", "wsoft.techniques.base",
                        "wsoft.bench", "wsoft.bench.harness", "wsoft.usd_scenes", "wsoft.parallel"})


class _WarpFirst(importlib.abc.MetaPathFinder):
    """Imports :mod:`wsoft.parallel` before the first other wsoft module, which may define Warp
    code: Warp's settings (``enable_backward``) are read when a Warp module is created, so they must
    be set before it. Finds nothing itself and leaves ``sys.meta_path`` after its first use."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname.startswith("wsoft.") and fullname not in _WARP_FREE:
            with _WARP_FIRST_LOCK:
                if self in sys.meta_path:
                    sys.meta_path.remove(self)
            if "wsoft.parallel" not in sys.modules:
                importlib.import_module("wsoft.parallel")
        return None


_WARP_FIRST_LOCK = threading.Lock()
if "wsoft.parallel" not in sys.modules:
    sys.meta_path.insert(0, _WarpFirst())


def __getattr__(name: str):
    """The lazy names above, and the subpackages (``wsoft.techniques.get_technique``) at first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


class _Package(types.ModuleType):
    """``wsoft.render`` is the function, as it was when this package imported it eagerly: importing
    the submodule ``wsoft.render`` (``sys.modules["wsoft.render"]``) does not rebind it; nor does
    importing ``wsoft.bake`` rebind the function ``wsoft.bake``."""

    def __setattr__(self, name, value):
        if name in ("render", "bake") and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
