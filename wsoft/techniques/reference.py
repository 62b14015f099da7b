"""``reference``: ray-traced ground truth (see :mod:`wsoft.reference`).

Writes ``visibility`` and ``V_stderr``, the per-pixel standard error. UsdLux's shadow controls are
exact here: prims a light's ``collection:shadowLink`` leaves out are passed through by its rays
(as a cutout's holes are), and ``inputs:shadow:distance`` ends each ray that far from the receiver. ``samples`` is its
quality knob: error falls as 1/sqrt(samples) (faster where the stratification helps), time
grows linearly.

Example::

    ref = wsoft.render(scene, "reference", width=640, height=480, samples=256)
"""

from __future__ import annotations

from dataclasses import dataclass

from wsoft.lightspace.light import disk_shaped
from wsoft.reference import TRAVERSALS, reference_pattern, trace_reference
from wsoft.reference.dome import trace_dome_reference
from wsoft.scene.dome import is_dome
from wsoft.scene.device import upload_scene
from wsoft.params import check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param


@dataclass(frozen=True)
class ReferenceParams:
    samples: int = param(256, "light samples per pixel sample (stratified; perfect squares use a jittered grid)", range=(1, 1 << 20))
    seed: int = param(0, "random seed", range=(0, 2**31 - 1))
    jitter: bool = param(True, "jitter inside strata (false: stratum centres; one sample = the light's centre)")
    casters: str = param("all", "which prims occlude: all, or dynamic (the ground truth of a dynamic-caster shadow mask)")
    traversal: str = param("auto", "BVH traversal: packet (a receiver's light samples 32 at a time), ray (one by one), auto (packet on CPU "
                                   "from 8 samples, else ray); the same answer bit for bit")

    def __post_init__(self):
        check_ranges(self)
        check(1 <= self.samples <= 1 << 20, f"samples {self.samples} out of range [1, 1048576]")
        check(self.casters in ("all", "dynamic"), f"casters {self.casters!r} is not all or dynamic")
        check(self.traversal in TRAVERSALS, f"traversal {self.traversal!r} is not one of {', '.join(TRAVERSALS)}")


class Reference(Technique):
    """Ray-traced visible fraction of the light with many stratified samples."""

    name = "reference"
    instancing_refusal = ""  # rays go through the instances' top-level BVH (wsoft.scene.instancing)
    summary = "ray-traced ground truth: stratified light samples, BVH any-hit, alpha-tested, with standard error"
    Params = ReferenceParams
    # the visibility carries its standard error (V_stderr)
    passes = (PassSpec("trace", reads=("gbuffer", "scene"), writes=("visibility",)),)
    quick_params = {"samples": 4}
    quality = (Quality("samples", (1, 4, 16, 64, 256), "more light samples: error down as 1/sqrt(samples), time up linearly"),)
    tolerance = Tolerance(mae=0.0003, mae_penumbra=0.01)
    horizon = "exact"  # per light sample, in the tracing kernel
    cylinder_model = "its silhouette rectangle seen from each point, sampled (a line light: its segment)"
    dome_refusal = ""  # a DomeLight: rays over each receiver's hemisphere (wsoft.reference.dome)

    def supports(self, scene, light) -> str | None:
        why = super().supports(scene, light)
        if why is not None:
            return why
        if self.params.casters == "dynamic" and (scene.tri_dynamic is None or not scene.tri_dynamic.any()):
            return "casters=dynamic but the scene has no dynamic prims"
        return None

    def instancing_why(self) -> str:
        if self.params.casters == "dynamic":
            return "casters=dynamic traces the soup's dynamic triangles"
        return ""

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        scene_key = ctx.scene_arrays()
        out = ctx.visibility_key(light)
        scene = ctx.scene
        dynamic = p.casters == "dynamic"
        if is_dome(light):
            return self._add_dome_pass(ctx, light, gbuf, scene_key, out)
        L = ctx.light_gpu(light)
        pattern = reference_pattern(p.samples, ctx.frame_seed(p.seed), p.jitter)
        disk = disk_shaped(light)

        name = ("reference_alpha" if scene.has_cutouts else "reference") + ("_dynamic" if dynamic else "")
        pass_name = ctx.pass_name(name, light)

        def run(res):
            ds = res[scene_key]
            if dynamic:  # occluders: the dynamic casters only (their own BVH, built once per device)
                ds, _ = scene.dynamic_subset().device_copy(ctx.device, upload_scene)
            counters = ctx.counters(light)
            vis, err = trace_reference(ds, L, res[gbuf], pattern, disk, p.traversal, counters,
                                       excluded=light.shadow_excluded, max_distance=light.shadow_distance)
            if "packet_fallback" in counters:
                ctx.ctx.warn(pass_name, f"traced ray by ray, not in packets: {counters['packet_fallback']}")
            return {out: ctx.visibility(vis, err)}

        return ctx.add_pass(pass_name, inputs=(gbuf, scene_key), outputs=(out,), run=run, stage="trace", light=light)

    def _add_dome_pass(self, ctx, light, gbuf, scene_key, out):
        """The dome's pass: ``samples`` rays over each receiver's hemisphere (:mod:`wsoft.reference.dome`)."""
        p = self.params
        scene = ctx.scene
        dynamic = p.casters == "dynamic"
        pass_name = ctx.pass_name(("reference_dome_alpha" if scene.has_cutouts else "reference_dome") + ("_dynamic" if dynamic else ""),
                                  light)

        def run(res):
            ds = res[scene_key]
            if dynamic:
                ds, _ = scene.dynamic_subset().device_copy(ctx.device, upload_scene)
            vis, err = trace_dome_reference(ds, light, res[gbuf], p.samples, ctx.frame_seed(p.seed), excluded=light.shadow_excluded,
                                            max_distance=light.shadow_distance)
            return {out: ctx.visibility(vis, err)}

        return ctx.add_pass(pass_name, inputs=(gbuf, scene_key), outputs=(out,), run=run, stage="trace", light=light)
