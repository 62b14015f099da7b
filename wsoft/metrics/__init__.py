"""Error of a visibility image against the reference, on the same (covered) pixels, as a pass of
the frame graph.

:func:`visibility_error` is the arithmetic: MAE, RMSE, max, the MAE in the penumbra (reference
strictly between 0.01 and 0.99), the share of pixels further than 3 reference standard errors,
and the same split into receivers that face the light's centre and those that do not (the
answer there is 0: filtered techniques that leak light show it). A NaN in the image is counted,
warned about and scored as an error of 1, never dropped.

:func:`add_error_pass` registers that computation as a ``metric`` pass comparing a technique's
channels with the reference's (another technique of the same graph, or a :class:`GroundTruth`
computed earlier and handed in); where both carry a shaded image (``R``, ``G``, ``B``) it adds
ꟻLIP (:mod:`wsoft.metrics.flip`), measured once per technique by :func:`add_flip_pass`.
:func:`compare` renders techniques and the reference in one graph and returns the frames with
``stats["errors"]`` and each technique's ꟻLIP map in ``Frame.error_maps["flip"]``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from wsoft.graph import Key, Pass
from wsoft.metrics.flip import RGB, flip_error, has_rgb
from wsoft.scene.types import LIGHT_DISTANT, Light

PENUMBRA_LO = 0.01
PENUMBRA_HI = 0.99


def _summary(d: np.ndarray, pen: np.ndarray) -> dict:
    if d.size == 0:
        return {"pixels": 0, "mae": 0.0, "mae_penumbra": 0.0, "penumbra_pixels": 0}
    return {"pixels": int(d.size), "mae": float(d.mean()), "mae_penumbra": float(d[pen].mean()) if pen.any() else 0.0,
            "penumbra_pixels": int(pen.sum())}


def visibility_error(v: np.ndarray, ref: np.ndarray, ref_stderr: np.ndarray | None = None, coverage: np.ndarray | None = None,
                     facing: np.ndarray | None = None) -> dict:
    """MAE, RMSE, max, MAE in the penumbra, the fraction of pixels outside 3 reference stderr, the
    non-finite pixels of ``v`` (each scored 1), and with ``facing`` (bool [H, W]) the same for the
    pixels that face the light and those that do not. Pixels count where ``coverage > 0``."""
    v = np.asarray(v, np.float64)
    ref = np.asarray(ref, np.float64)
    if v.shape != ref.shape:
        raise ValueError(f"image {v.shape} and reference {ref.shape} differ in size")
    mask = np.ones(v.shape, bool) if coverage is None else np.asarray(coverage) > 0
    n = int(mask.sum())
    bad = ~np.isfinite(v) & mask
    nan_pixels = int(bad.sum())
    if nan_pixels:
        warnings.warn(f"{nan_pixels} pixels of the image are not finite; each counts as an error of 1", RuntimeWarning, stacklevel=2)
    if n == 0:
        return {"pixels": 0, "mae": 0.0, "rmse": 0.0, "max": 0.0, "mae_penumbra": 0.0, "penumbra_pixels": 0, "frac_outside_3se": 0.0,
                "nan_pixels": 0}
    diff = np.where(np.isfinite(v), np.abs(v - ref), 1.0)
    d = diff[mask]
    pen_img = (ref > PENUMBRA_LO) & (ref < PENUMBRA_HI)
    pen = pen_img[mask]
    out = {
        "pixels": n,
        "mae": float(d.mean()),
        "rmse": float(np.sqrt((d * d).mean())),
        "max": float(d.max()),
        "mae_penumbra": float(d[pen].mean()) if pen.any() else 0.0,
        "penumbra_pixels": int(pen.sum()),
        "nan_pixels": nan_pixels,
    }
    if ref_stderr is not None:
        se = np.asarray(ref_stderr, np.float64)[mask]
        out["frac_outside_3se"] = float(np.mean(d > 3.0 * se))
    if facing is not None:
        f = np.asarray(facing, bool)
        out["facing"] = _summary(diff[mask & f], pen_img[mask & f])
        out["not_facing"] = _summary(diff[mask & ~f], pen_img[mask & ~f])
    return out


def facing_light(channels: dict, light: Light) -> np.ndarray:
    """Pixels whose (camera-facing) normal faces the light's centre (a distant light: its direction)."""
    n = np.stack([channels["N.X"], channels["N.Y"], channels["N.Z"]], -1)
    if light.kind == LIGHT_DISTANT:
        return n @ light.frame[:, 2] > 0.0
    p = np.stack([channels["P.X"], channels["P.Y"], channels["P.Z"]], -1)
    return np.einsum("...i,...i->...", n, np.asarray(light.position) - p) > 0.0


@dataclass
class GroundTruth:
    """A reference computed earlier (a cached one): per light label, its ``V``, ``V_stderr`` and
    ``A``; ``shaded``: its shaded image (``R``, ``G``, ``B``, float32 [H, W], linear) lit by the
    lights the compared frames render, which the error passes measure ꟻLIP against (None: no ꟻLIP)."""

    lights: dict[str, dict[str, np.ndarray]]
    samples: int
    shaded: dict[str, np.ndarray] | None = None

    def channels(self, label: str) -> dict[str, np.ndarray]:
        g = self.lights[label]
        out = {f"V.{label}": g["V"], f"V_stderr.{label}": g["V_stderr"], "A": g["A"]}
        if self.shaded is not None:
            out.update({c: self.shaded[c] for c in RGB})
        return out


def ground_truth_key(ctx, truth: GroundTruth, light: Light) -> Key:
    """Hand a :class:`GroundTruth` to the graph (a ``reference`` pass that does no work)."""
    label = ctx.label(light)
    key = Key("ground_truth", label, variant=f"@{truth.samples}")
    channels = truth.channels(label)
    crop = ctx.framing.crop if ctx.framing is not None else None
    if crop is not None and channels["A"].shape == (ctx.height, ctx.width):  # a whole image: its data window
        x0, y0, x1, y1 = crop
        channels = {k: v[y0:y1, x0:x1] for k, v in channels.items()}
    return ctx.provide(key, channels, name=f"ground_truth[{label}]@{truth.samples}", kind="reference")


def add_flip_pass(ctx, technique_label: str, channels: Key, reference: Key) -> Key:
    """A ``metric`` pass ``flip[<technique>]``: ꟻLIP of the technique's shaded image against the
    reference's (:func:`wsoft.metrics.flip.flip_error`), once per technique and frame. Its resource
    is ``{"error": {flip, flip_covered, flip_nan_pixels}, "map": float32 [H, W]}``, or None when
    either side has no ``R``, ``G``, ``B``. A technique has one shaded image whatever its lights, so
    the first call registers the pass (against that call's ``reference``) and later calls return
    its key: the references of one technique's lights must carry the same shaded image (a
    :class:`GroundTruth` gives every light its ``shaded``)."""
    key = Key("flip", technique=technique_label)
    if key in ctx.graph.producers:
        return key

    def run(res):
        ch, ref = res[channels], res[reference]
        if not (has_rgb(ch) and has_rgb(ref)):
            return {key: None}
        err, emap = flip_error(ch, ref)
        return {key: {"error": err, "map": emap}}

    return ctx.add(Pass(f"flip[{technique_label}]", (channels, reference), (key,), run, kind="metric", technique=technique_label))


def add_error_pass(ctx, technique_label: str, channels: Key, reference: Key, light: Light) -> Key:
    """A ``metric`` pass: the error of a technique's ``V.<light>`` (from its ``channels``) against
    the reference's (``reference``: a technique's channels or a ground-truth key).

    Where both carry ``R``, ``G``, ``B`` the error also holds ``flip`` (ꟻLIP's mean over the whole
    image), ``flip_covered`` (over the reference's covered pixels) and ``flip_nan_pixels``, from
    the technique's one :func:`add_flip_pass`. The shaded image combines every light the technique
    renders, so the errors of its several lights carry the same ꟻLIP values."""
    label = ctx.label(light)
    key = Key("error", label, technique=technique_label)
    flip = add_flip_pass(ctx, technique_label, channels, reference)

    def run(res):
        ch, ref = res[channels], res[reference]
        reach = ch.get(f"reach.{label}")  # a shaped light: pixels its cone does not reach have no shadow of it (docs/outputs.md)
        cover = ref["A"] if reach is None else np.where(reach > 0, ref["A"], 0.0)
        out = visibility_error(ch[f"V.{label}"], ref[f"V.{label}"], ref.get(f"V_stderr.{label}"), cover, facing=facing_light(ch, light))
        if reach is not None:
            out["unreached_pixels"] = int(np.count_nonzero((np.asarray(ref["A"]) > 0) & ~(reach > 0)))
        if res[flip] is not None:
            out.update(res[flip]["error"])
        return {key: out}

    return ctx.add(Pass(f"error[{technique_label}:{label}]", (channels, reference, flip), (key,), run, kind="metric",
                        technique=technique_label, light=label))


def compare(scene, techniques, *, samples: int = 256, ground_truth: GroundTruth | None = None, width: int | None = None,
            height: int | None = None, camera=None, light=None, device: str | None = None, pixel_samples: int = 1,
            time_code: float | None = None, render_settings: str | None = None, progress=None, frame_history=None):
    """Render ``techniques`` (as :func:`wsoft.render` takes a list) and the reference in one graph,
    and measure each technique's error against the reference on the same pixels.

    The reference is ``reference`` with ``samples`` light samples (added unless the list holds a
    reference already), or ``ground_truth`` computed earlier. Returns the
    :class:`~wsoft.pipeline.FrameSet`; each technique's ``stats["errors"]`` maps light label ->
    error (:func:`add_error_pass`: with ꟻLIP where both shaded images exist), ``stats["error"]`` is
    the first light's, and ``error_maps["flip"]`` holds its ꟻLIP map (float32 [H, W]). ``width``,
    ``height``, ``camera``, ``render_settings``, ``progress``, ``frame_history``: as :func:`wsoft.render` takes them
    (errors are measured on the data window's pixels when the settings have one)."""
    import time

    from wsoft.parallel import compile_time, resolve_device
    from wsoft.pipeline import check_sizes, as_techniques, build_graph, execute, frames_of, is_several, with_render_settings
    from wsoft.techniques import create

    scene = with_render_settings(scene, render_settings, time_code)
    check_sizes(width, height, pixel_samples)
    techs = as_techniques(list(techniques) if is_several(techniques) else [techniques], {})
    ref_label = None
    if ground_truth is None:
        refs = [t for t in techs if t.name == "reference"]
        if not refs:
            techs.append(create("reference", {"samples": samples}))
    dev = resolve_device(device)
    t0 = time.perf_counter()
    built = build_graph(scene, techs, width=width, height=height, camera=camera, light=light, device=dev, pixel_samples=pixel_samples,
                        history=frame_history)
    ctx = built.ctx
    if ground_truth is None:
        ref_label = next(label for t, label in zip(built.techniques, built.labels) if t.name == "reference")
    errors: dict[str, dict[str, Key]] = {}
    for tech, label in zip(built.techniques, built.labels):
        if label == ref_label or label not in built.channels:
            continue
        for l in built.lights[label]:
            ref_key = built.channels[ref_label] if ground_truth is None else ground_truth_key(ctx, ground_truth, l)
            errors.setdefault(label, {})[ctx.label(l)] = add_error_pass(ctx, label, built.channels[label], ref_key, l)
    flips = {label: Key("flip", technique=label) for label in errors}
    extra = [k for m in errors.values() for k in m.values()] + list(flips.values())
    res, records, _ = execute(built, dev, extra=extra, progress=progress)
    t1 = time.perf_counter()
    fs = frames_of(built, res, records, 1e3 * (t1 - t0), compile_ms=1e3 * compile_time(t0, t1)[0])
    for label, m in errors.items():
        st = fs[label].stats
        st["errors"] = {ll: res[k] for ll, k in m.items()}
        st["error"] = st["errors"][st["light_labels"][0]]
        st["error_against"] = f"reference ({ground_truth.samples if ground_truth else built.techniques[built.labels.index(ref_label)].params.samples} samples)"
        if res[flips[label]] is not None:
            fs[label].error_maps["flip"] = res[flips[label]]["map"]
    fs.stats["reference"] = ref_label
    return fs
