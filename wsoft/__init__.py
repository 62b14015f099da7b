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
"""

import wsoft.parallel  # noqa: F401  (sets Warp quiet before any kernel loads)
from wsoft.errors import ParameterError, SceneError, WsoftError
from wsoft.render import Frame, FrameSet, plan, render
from wsoft.scene import Scene, load_scene
from wsoft.techniques import TECHNIQUES
from wsoft.metrics import compare  # noqa: E402  (above render in the layers)

__version__ = "0.1.0"
__all__ = ["Frame", "FrameSet", "ParameterError", "Scene", "SceneError", "TECHNIQUES", "WsoftError", "compare", "load_scene", "plan", "render"]
