"""wsoft: real-time soft-shadow techniques in NVIDIA Warp, on scenes from USD stages.

Python API::

    import wsoft
    scene = wsoft.load_scene("usd_scenes/box_plane.usda")
    frame = wsoft.render(scene, "hard", width=640, height=480, shadow_map_size=2048)
    ref = wsoft.render(scene, "reference", width=640, height=480, samples=256)
    frame.write_exr("hard.exr"); print(frame.stats["timings_ms"])
"""

import wsoft.parallel  # noqa: F401  (sets Warp quiet before any kernel loads)
from wsoft.errors import ParameterError, SceneError, WsoftError
from wsoft.render import Frame, plan, render
from wsoft.scene import Scene, load_scene
from wsoft.techniques import TECHNIQUES

__version__ = "0.1.0"
__all__ = ["Frame", "ParameterError", "Scene", "SceneError", "TECHNIQUES", "WsoftError", "load_scene", "plan", "render"]
