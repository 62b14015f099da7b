"""``reference``: ray-traced ground truth (see :mod:`wsoft.reference`).

| parameter | type | default | meaning |
|---|---|---|---|
| samples | int | 256 | light samples per G-buffer sample (stratified) |
| seed | int | 0 | random seed (deterministic for a given seed) |
| jitter | bool | true | jitter inside strata; false puts samples at stratum centres (1 sample = the light's centre) |

Writes ``visibility`` and ``V_stderr``, the per-pixel standard error.
"""

from __future__ import annotations

from dataclasses import dataclass

from wsoft.lightspace.light import disk_shaped
from wsoft.reference import reference_pattern, trace_reference
from wsoft.scene.device import upload_scene
from wsoft.techniques.base import Technique, check, param


@dataclass(frozen=True)
class ReferenceParams:
    samples: int = param(256, "light samples per pixel sample (stratified; perfect squares use a jittered grid)")
    seed: int = param(0, "random seed")
    jitter: bool = param(True, "jitter inside strata (false: stratum centres; one sample = the light's centre)")
    casters: str = param("all", "which prims occlude: all, or dynamic (the ground truth of a dynamic-caster shadow mask)")

    def __post_init__(self):
        check(1 <= self.samples <= 1 << 20, f"samples {self.samples} out of range [1, 1048576]")
        check(self.casters in ("all", "dynamic"), f"casters {self.casters!r} is not all or dynamic")


class Reference(Technique):
    """Ray-traced visible fraction of the light with many stratified samples."""

    name = "reference"
    summary = "ray-traced ground truth: stratified light samples, BVH any-hit, alpha-tested, with standard error"
    Params = ReferenceParams
    reads = ("gbuffer", "scene.bvh", "scene.triangles", "scene.textures")
    writes = ("visibility", "V_stderr")

    def add_passes(self, ctx, light) -> str:
        p = self.params
        gbuf = ctx.gbuffer()
        scene_key = ctx.scene_arrays()
        out = ctx.visibility_key(light)
        L = ctx.light_gpu(light)
        scene = ctx.scene
        dynamic = p.casters == "dynamic"
        if dynamic and (scene.tri_dynamic is None or not scene.tri_dynamic.any()):
            from wsoft.errors import ParameterError

            raise ParameterError("reference: casters=dynamic but the scene has no dynamic prims", file=scene.path)

        def run(res):
            ds = res[scene_key]
            if dynamic:  # occluders: the dynamic casters only (their own BVH, built once per device)
                ds, _ = scene.dynamic_subset().device_copy(ctx.device, upload_scene)
            vis, err = trace_reference(ds, L, res[gbuf], reference_pattern(p.samples, p.seed, p.jitter), disk_shaped(light))
            return {out: ctx.visibility(vis, err)}

        name = ("reference_alpha" if scene.has_cutouts else "reference") + ("_dynamic" if dynamic else "")
        ctx.add_pass(f"{name}[{ctx.label(light)}]", inputs=(gbuf, scene_key), outputs=(out,), run=run, kind="technique")
        return out
