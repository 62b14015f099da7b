"""A sequence's errors: each frame against its ground truth and the sequence's temporal measures.

:func:`compare_sequence` renders techniques at every time code of a stage
(:func:`wsoft.pipeline.sequence.render_sequence`'s loading, sharing and history) beside a ground
truth per frame (the reference at ``samples``, seed 0 in every frame: its noise does not crawl),
measures each frame's error as :func:`wsoft.compare` does, and over the frames the measures of
:mod:`wsoft.metrics.temporal` (:func:`temporal_measures`): flicker against the ground truth (pixels
paired through the camera's motion), mean and worst error, the ground truth's noise floor.
"""

from __future__ import annotations

import time as _time

import numpy as np

from wsoft.scene.types import Scene
from wsoft.pipeline.sequence import Sequence, cost_summary, frame_costs, note_upload, stage_is_animated, stamp_frame, start_sequence


def ground_truth_frame(scene: Scene, samples: int, *, width, height, camera, light, device, pixel_samples: int = 1):
    """The reference at ``samples`` light samples (seed 0) on ``scene`` as a
    :class:`~wsoft.metrics.GroundTruth` (every light it renders), and the frame itself."""
    from wsoft.metrics import GroundTruth
    from wsoft.pipeline import render

    fr = render(scene, "reference", width=width, height=height, camera=camera, light=light, device=device, pixel_samples=pixel_samples,
                samples=samples, seed=0)
    lights = {label: {"V": fr[f"V.{label}"], "V_stderr": fr[f"V_stderr.{label}"], "A": fr["A"]} for label in fr.stats["light_labels"]}
    return GroundTruth(lights, samples, shaded={c: fr[c] for c in "RGB"}), fr


def compare_sequence(scene, techniques, *, frames, samples: int = 256, ground_truth=None, width: int | None = None,
                     height: int | None = None, camera=None, light=None, device: str | None = None, pixel_samples: int = 1,
                     render_settings: str | None = None, instancing: str = "auto", reseed: bool = True, progress=None,
                     subdiv_level: int | None = None, material_purpose: str | None = None) -> Sequence:
    """Render ``techniques`` at every time code of ``frames`` beside a ground truth and measure each
    frame's error (as :func:`wsoft.compare`) and the sequence's temporal error.

    The ground truth of frame t is the reference at ``samples`` light samples with seed 0 in every
    frame, or ``ground_truth(scene_t, t)`` returning a :class:`~wsoft.metrics.GroundTruth` (the
    benchmark's cached references). Each frame is a :class:`~wsoft.pipeline.FrameSet` with
    ``stats["errors"]`` per technique; ``summary["temporal"][label][light]`` holds
    :func:`~wsoft.metrics.temporal.sequence_summary` (flicker against the ground truth, pixels
    paired through the camera's motion; mean and worst error; the ground truth's noise floor
    ``flicker_noise``; for a technique with standard errors, its own ``own_noise`` and
    ``flicker_excess``) and, on a static sequence (the stage authors no time sample),
    ``temporal_std`` (a stochastic technique's crawl) beside the reference's own.
    ``ground_truths`` holds each frame's :class:`~wsoft.metrics.GroundTruth`. ``subdiv_level`` and
    ``material_purpose``: as :func:`~wsoft.pipeline.sequence.render_sequence` takes them."""
    from wsoft.metrics import compare
    from wsoft.pipeline import as_techniques, is_several

    techs = as_techniques(list(techniques) if is_several(techniques) else [techniques], {})
    loader, seq, history = start_sequence(scene, frames, render_settings, instancing, techs, reseed, subdiv_level, material_purpose,
                                          width=width, height=height, camera=camera, light=light, device=device, pixel_samples=pixel_samples)
    times = seq.times
    truths: list = []
    for i, t in enumerate(times):
        sc, info = loader.load(t)
        if i == 0:
            seq.render_settings = sc.render_settings
        t0 = _time.perf_counter()
        if ground_truth is None:
            gt, _ = ground_truth_frame(sc, samples, width=width, height=height, camera=camera, light=light, device=device,
                                       pixel_samples=pixel_samples)
        else:
            gt = ground_truth(sc, t)
        info["ground_truth_ms"] = round(1e3 * (_time.perf_counter() - t0), 3)
        t0 = _time.perf_counter()
        fs = compare(sc, techs, ground_truth=gt, width=width, height=height, camera=camera, light=light, device=device,
                     pixel_samples=pixel_samples, frame_history=history)
        history.advance()
        info["render_ms"] = round(1e3 * (_time.perf_counter() - t0), 3)
        info["frame_ms"] = frame_costs(fs)
        note_upload(fs, info)
        stamp_frame(fs, info, i, len(times))
        seq.frames.append(fs)
        seq.stats.append(info)
        truths.append(gt)
        if progress is not None:
            progress(i + 1, len(times), t)
    seq.ground_truths = truths
    seq.summary = cost_summary(seq)
    seq.summary["temporal"] = temporal_measures(seq, truths, static=not stage_is_animated(loader.stage))
    seq.summary["ground_truth_samples"] = truths[0].samples if truths else samples
    return seq


def temporal_measures(seq: Sequence, truths: list, static: bool) -> dict:
    """Per technique label and light label: :func:`~wsoft.metrics.temporal.sequence_summary` over
    the frames of ``seq`` (each a FrameSet with errors) against ``truths`` (a GroundTruth per frame)."""
    from wsoft.metrics.temporal import FrameCamera, flicker, flicker_noise, pair_pixels, sequence_summary, temporal_std

    out: dict[str, dict] = {}
    if not seq.frames:
        return out
    labels = list(seq.frames[0])
    for label in labels:
        first = seq.frames[0][label]
        out[label] = {}
        for ll in first.stats["light_labels"]:
            pairs, noise, own, errors = [], [], [], []
            noisy = f"V_stderr.{ll}" in first.channels
            for k, fs in enumerate(seq.frames):
                fr = fs[label]
                errors.append(fr.stats["errors"][ll])
                if k == 0:
                    continue
                prev = seq.frames[k - 1][label]
                g0, g1 = truths[k - 1].lights[ll], truths[k].lights[ll]
                pp = pair_pixels(prev.channels, fr.channels, FrameCamera.of(prev.stats), FrameCamera.of(fr.stats))
                pairs.append(flicker(prev[f"V.{ll}"], fr[f"V.{ll}"], g0["V"], g1["V"], pp))
                noise.append(flicker_noise(g0["V_stderr"], g1["V_stderr"], pp))
                if noisy:
                    own.append(flicker_noise(prev[f"V_stderr.{ll}"], fr[f"V_stderr.{ll}"], pp))
            s = sequence_summary(pairs, errors, seq.times, noise, own if noisy else None)
            if static and len(seq.frames) > 1:
                covered = np.all([np.asarray(fs[label]["A"]) > 0 for fs in seq.frames], axis=0)
                s["temporal_std"] = temporal_std([fs[label][f"V.{ll}"] for fs in seq.frames], covered)
                s["reference_temporal_std"] = temporal_std([g.lights[ll]["V"] for g in truths], covered)
            out[label][ll] = s
    return out
