"""Scenes: USD stages turned into world-space triangles, materials, lights and cameras."""

import wsoft.parallel  # noqa: F401  (Warp configured before this package's kernels are defined)
from wsoft.scene.render_settings import RenderProduct, RenderSettings
from wsoft.scene.types import Camera, Light, Material, Scene, SkippedLight, Texture
from wsoft.scene.usd import load_scene
from wsoft.scene.usd_lights import auto_camera

__all__ = ["Camera", "Light", "Material", "RenderProduct", "RenderSettings", "Scene", "SkippedLight", "Texture", "auto_camera",
           "load_scene"]
