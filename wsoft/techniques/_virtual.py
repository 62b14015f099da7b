"""What ``vsmap`` and ``smrt`` declare alike: both read a virtual shadow map whose pages are
requested at each pixel's footprint (:mod:`wsoft.accel.virtual_passes`), drawn by the shared
rasterizer (instances included), keeping the caster nearest the light only, and declining cylinder
lights. This module holds no technique of its own (the registry skips modules whose name starts
with ``_``)."""

from __future__ import annotations

from wsoft.accel.virtual_passes import CYLINDER_MODEL, DISTANCE_REFUSAL, cylinder_refusal
from wsoft.techniques.base import Technique


class VirtualMapTechnique(Technique):
    """Base class of ``vsmap`` and ``smrt`` (module docstring); a subclass declares its own passes,
    parameters (with a ``footprint``: world units, 0 to take it from the camera) and refusals of
    point lights and cube maps."""

    instancing_refusal = ""  # its pages are drawn by the shared rasterizer, instances included
    distance_refusal = DISTANCE_REFUSAL
    cylinder_model = CYLINDER_MODEL

    def bake_support(self) -> str | None:
        if self.params.footprint > 0.0:
            return None
        return (f"{self.name} requests its pages at each pixel's footprint seen from the camera; a bake has no camera: "
                "set footprint= (world units)")

    def supports(self, scene, light):
        return cylinder_refusal(light) or super().supports(scene, light)
