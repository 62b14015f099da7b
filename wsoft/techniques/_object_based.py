"""The frame of the object-based techniques (``dcs``, ``pwedge``; Forest et al. 2008, 2009): their
common light-sample parameters, and the three passes each adds per light, of which each
technique supplies its own parts.

1. ``edges`` — the technique's silhouette edges (:meth:`ObjectBased.edges`), binned in a
   light-space grid of ``grid_size`` cells fitted to the receivers, beside a BVH of the light's
   opaque casters (:func:`~wsoft.accel.occluders.edge_pass`);
2. ``stsv`` — only when the light's casters hold perforated (cutout) triangles: their soft
   textured shadow volumes, binned in the same grid (:func:`~wsoft.accel.occluders.perforated_volumes`),
   and what the technique derives from them per receiver (:meth:`ObjectBased.perforated`);
3. the visibility pass (:attr:`ObjectBased.final_stage`): the technique's estimator
   (:meth:`ObjectBased.visibility`), each receiver gathering the edges and volumes of its cell.

This module holds no technique of its own (the registry skips modules whose name starts with ``_``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from wsoft.accel.occluders import Prep, edge_pass, perforated_volumes, triangle_masks
from wsoft.lightspace.samples import KINDS, SamplePattern, check_decorrelation, paper_pattern
from wsoft.params import check_ranges
from wsoft.techniques.base import PassSpec, Technique, check, param


@dataclass(frozen=True)
class ObjectBasedParams:
    """The light samples and the binning grid of an object-based technique; a technique's own
    ``Params`` subclasses it and adds ``samples`` (and its own knobs)."""

    pattern: str = param("stratified", "light-sample pattern: " + ", ".join(KINDS) + " (poisson: the paper's minimum distances at 16 "
                                       "and 64)")
    decorrelate: str = param("rotate", "between pixels: rotate (the set turned per pixel), interleave (n x n sets), per_pixel (a new set "
                                       "per pixel: with pattern=stratified the reference's own samples), none (one set everywhere)")
    interleave: int = param(4, "decorrelate=interleave: n of the n x n interleaved sets", range=(1, 16))
    seed: int = param(0, "random seed of the sample sets", range=(0, 2**31 - 1))
    grid_size: int = param(128, "cells per side of the light-space grid (a light view fitted to the receivers) that bins receivers "
                                "against silhouette edges and perforated triangles' volumes", range=(8, 4096))

    def __post_init__(self):
        check_ranges(self)
        self.check_samples()
        why = check_decorrelation(self.pattern, self.samples, self.decorrelate)
        check(why is None, why)

    def check_samples(self) -> None:
        """A technique's own rule for its sample count (in range already), checked before the pattern's."""

    def sample_pattern(self) -> SamplePattern:
        return paper_pattern(self.pattern, self.samples, self.seed, self.decorrelate, self.interleave)


def object_based_passes(name: str, final_stage: str) -> tuple[PassSpec, ...]:
    """The passes of the object-based technique ``name`` (its resources are ``<name>_edges`` and
    ``<name>_stsv``), its visibility pass of stage ``final_stage``."""
    edges, stsv = f"{name}_edges", f"{name}_stsv"
    return (
        PassSpec("edges", reads=("gbuffer", "scene"), writes=(edges,)),
        PassSpec("stsv", reads=("gbuffer", "scene", edges), writes=(stsv,),
                 when="the light's casters hold perforated triangles not wholly behind the light"),
        PassSpec(final_stage, reads=("gbuffer", "scene", edges), optional=(stsv,), writes=("visibility",)),
    )


class ObjectBased(Technique):
    """Base class of ``dcs`` and ``pwedge`` (module docstring): :meth:`add_passes` is theirs; a
    subclass implements :meth:`edges`, :meth:`visibility` and, when its volumes feed a pass of their
    own, :meth:`perforated`, and declares ``passes = object_based_passes(name, final_stage)``."""

    final_stage: ClassVar[str]
    size_param = "grid_size"

    def edges(self, scene, opaque: np.ndarray, light, device) -> tuple[np.ndarray, dict, dict]:  # pragma: no cover - interface
        """The light's silhouette edges for this technique: (corners [E, 2, 3] float32 to bin, the
        device arrays its visibility kernel reads, counters)."""
        raise NotImplementedError

    def perforated(self, ctx, light, gb, ds, counters: dict, data: dict) -> tuple[dict, dict]:
        """What the ``stsv`` pass keeps of the perforated triangles' binned volumes (``data``, as
        :func:`~wsoft.accel.occluders.perforated_volumes` builds them) and its counters: as they are."""
        return counters, data

    def visibility(self, ctx, light, gb, ds, prep: Prep, st: Prep | None):  # pragma: no cover - interface
        """Per G-buffer sample visibility (a flat float32 array) and counters, from the edge pass's
        ``prep`` and the ``stsv`` pass's ``st`` (None without perforated triangles)."""
        raise NotImplementedError

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        scene_key = ctx.scene_arrays()
        scene = ctx.scene
        opaque, perforated = triangle_masks(scene, light)
        edges_key = ctx.key(f"{self.name}_edges", light)
        edges_name = ctx.pass_name(f"{self.name}_edges", light)

        def run_edges(res):
            corners, arrays, counters = self.edges(scene, opaque, light, ctx.device)
            prep = edge_pass(ctx, light, res[gbuf], scene, opaque, perforated, p.grid_size, corners, edges_name, arrays, counters)
            return {edges_key: prep}

        ctx.add_pass(edges_name, inputs=(gbuf, scene_key), outputs=(edges_key,), run=run_edges, stage="edges", light=light)
        inputs = [gbuf, scene_key, edges_key]
        stsv_key = None
        if perforated.any():
            stsv_key = ctx.key(f"{self.name}_stsv", light)
            inputs.append(stsv_key)
            L = ctx.light_gpu(light)

            def run_stsv(res):
                prep = res[edges_key]
                counters, data = perforated_volumes(scene, perforated, L, light, prep.view, prep.zr_max, ctx.device)
                counters, data = self.perforated(ctx, light, res[gbuf], res[scene_key], counters, data)
                return {stsv_key: Prep(view=prep.view, zr_max=prep.zr_max, counters=counters, data=data)}

            ctx.add_pass(ctx.pass_name(f"{self.name}_stsv", light), inputs=(gbuf, scene_key, edges_key), outputs=(stsv_key,), run=run_stsv,
                         stage="stsv", light=light)
        out = ctx.visibility_key(light)

        def run(res):
            prep = res[edges_key]
            st = res[stsv_key] if stsv_key is not None else None
            vis, counters = self.visibility(ctx, light, res[gbuf], res[scene_key], prep, st)
            c = ctx.counters(light)
            c.update(prep.counters)
            if st is not None:
                c.update(st.counters)
            c.update(counters)
            c["samples"] = p.samples
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(ctx.pass_name(self.name, light), inputs=tuple(inputs), outputs=(out,), run=run, stage=self.final_stage,
                            light=light)
