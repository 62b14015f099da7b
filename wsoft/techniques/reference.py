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

from wsoft.reference import trace_reference
from wsoft.techniques.base import Technique, check, param


@dataclass(frozen=True)
class ReferenceParams:
    samples: int = param(256, "light samples per pixel sample (stratified; perfect squares use a jittered grid)")
    seed: int = param(0, "random seed")
    jitter: bool = param(True, "jitter inside strata (false: stratum centres; one sample = the light's centre)")

    def __post_init__(self):
        check(1 <= self.samples <= 1 << 20, f"samples {self.samples} out of range [1, 1048576]")


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

        def run(res):
            vis, err = trace_reference(res[scene_key], L, res[gbuf], p.samples, p.seed, p.jitter)
            return {out: ctx.visibility(vis, err)}

        name = "reference_alpha" if ctx.scene.has_cutouts else "reference"
        ctx.add_pass(f"{name}[{ctx.label(light)}]", inputs=(gbuf, scene_key), outputs=(out,), run=run, kind="technique")
        return out
