"""The frame of the prefiltered shadow maps (``vsm``, ``esm``, ``msm``, ``evsm``): a map made from the light's depth
map and blurred (the ``map`` pass, shared by instances whose map size and named parameters agree),
then each G-buffer sample shaded from it (the ``shadow`` pass). A technique supplies how the map
is made (:meth:`Prefiltered.prefilter`) and read (:meth:`Prefiltered.shade`). This module holds no
technique of its own (the registry skips modules whose name starts with ``_``)."""

from __future__ import annotations

from typing import ClassVar

from wsoft.techniques.base import PassSpec, Technique


def prefiltered_passes(map_kind: str, map_stage: str) -> tuple[PassSpec, ...]:
    """The passes of a prefiltered technique whose map is a ``map_kind`` made in stage ``map_stage``."""
    return (
        PassSpec(map_stage, reads=("light_depth",), writes=(map_kind,)),
        PassSpec("shadow", reads=("gbuffer", "light_depth", map_kind), writes=("visibility",)),
    )


def normalised_bias(bias: float, view) -> float:
    """A depth bias given as a fraction of the frame's extent, in the view's normalised depth."""
    return bias * view.extent / max(view.far - view.near, 1e-12)


class Prefiltered(Technique):
    """Base class of ``vsm``, ``esm``, ``msm`` and ``evsm`` (module docstring): :meth:`add_passes` is theirs; a subclass
    declares ``map_kind``, ``map_stage``, ``map_params`` (the parameters the map depends on besides
    the map size) and ``passes = prefiltered_passes(map_kind, map_stage)``, and implements
    :meth:`prefilter` and :meth:`shade`."""

    map_kind: ClassVar[str]
    map_stage: ClassVar[str]
    map_params: ClassVar[tuple[str, ...]]
    size_param = "shadow_map_size"
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    cylinder_model = ("the shadow of its centre through a prefiltered map (its size plays no part), in a light view that looks at the "
                      "receivers as a sphere light's does")

    def prefilter(self, dm, device: str):  # pragma: no cover - interface
        """The prefiltered map ``[H, W]`` of the depth map ``dm``."""
        raise NotImplementedError

    def shade(self, gb, dm, fmap, device: str):  # pragma: no cover - interface
        """Per G-buffer sample visibility (a flat float32 array) from the prefiltered map ``fmap``."""
        raise NotImplementedError

    def cube_guard_texels(self) -> float:
        """Its prefilter's radius and the bilinear read's texel."""
        return float(self.params.radius) + 2.0

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        fkey = ctx.shared_key(self.map_kind, light, p.shadow_map_size, *self.map_params)
        out = ctx.visibility_key(light)

        def build(res):
            return {fkey: self.prefilter(res[depth], ctx.device)}

        def run(res):
            return {out: ctx.visibility(self.shade(res[gbuf], res[depth], res[fkey], ctx.device))}

        ctx.add_pass(str(fkey), inputs=(depth,), outputs=(fkey,), run=build, stage=self.map_stage, light=light)
        return ctx.add_pass(ctx.pass_name(self.name, light), inputs=(gbuf, depth, fkey), outputs=(out,), run=run, stage="shadow", light=light)
