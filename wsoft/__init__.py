"""wsoft: real-time soft-shadow techniques in NVIDIA Warp, on scenes from USD stages.

Python API::

    import wsoft
    scene = wsoft.load_scene("box_plane")   # a bundled stage's name, or any USD file
    frame = wsoft.render(scene, "hard", width=640, height=480, shadow_map_size=2048)
    ref = wsoft.render(scene, "reference", width=640, height=480, samples=256)
    frame.write_exr("hard.exr"); print(frame.stats["timings_ms"])

    # several techniques in one frame graph, sharing what they have in common
    frames = wsoft.render(scene, ["pcss", ("essm", {"H": 2.0}), "reference"])
    frames["essm"].V, frames.stats["shared_passes"]

    # and their error against the reference, measured by a metric pass
    result = wsoft.compare(scene, ["pcss", "essm"], samples=256)
    result["pcss"].stats["error"]["mae_penumbra"]
    wsoft.write_compare_grid("compare.png", result)   # shaded images and V - reference V, one grid

    # a sequence: the stage at each time code, flicker against the reference
    seq = wsoft.compare_sequence("ramp_slide", ["pcss", "hard"], frames="1:24")
    seq.summary["temporal"]["pcss"]["Light"]["flicker"], seq[3]["pcss"].V

    # visibility baked into USD: a layer of overs with primvars:wsoft:visibility:<light> per mesh
    layer = wsoft.bake("lightmapped_bridge", "pcss", frames="1:48", out="vis.usda")

The names below Warp or USD (everything but the exceptions) are imported at first use, so that
``import wsoft.cli`` and ``wsoft --help`` load neither. Every wsoft package that defines Warp code
imports :mod:`wsoft.parallel` first in its ``__init__`` (Warp quiet, no adjoint code), so its
kernels are configured however the package is reached.
"""

import importlib
import importlib.util

from wsoft.errors import ParameterError, SceneError, WsoftError

__version__ = "0.1.0"
__all__ = ["Frame", "FrameSet", "ParameterError", "Scene", "SceneError", "Sequence", "TECHNIQUES", "WsoftError", "bake", "compare",
           "compare_sequence", "load_scene", "plan", "render", "render_sequence", "write_compare_grid"]

# name -> the module that defines it, imported at first use
_LAZY = {
    "Frame": "wsoft.pipeline",
    "FrameSet": "wsoft.pipeline",
    "plan": "wsoft.pipeline",
    "render": "wsoft.pipeline",
    "Scene": "wsoft.scene",
    "load_scene": "wsoft.scene",
    "TECHNIQUES": "wsoft.techniques",
    "compare": "wsoft.metrics",
    "bake": "wsoft.baking",
    "Sequence": "wsoft.pipeline.sequence",
    "render_sequence": "wsoft.pipeline.sequence",
    "compare_sequence": "wsoft.metrics.sequences",
    "write_compare_grid": "wsoft.metrics.figures",
}


def __getattr__(name: str):
    """The lazy names above, and the subpackages (``wsoft.techniques.get_technique``) at first use."""
    if name in _LAZY:
        if _LAZY[name].startswith(("wsoft.pipeline", "wsoft.metrics", "wsoft.baking")):
            importlib.import_module("wsoft.auto")  # registers technique "auto" with the pipeline
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
