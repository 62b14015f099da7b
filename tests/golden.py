"""The golden frames: every bundled technique on every light of every bundled stage it supports,
48 x 36 pixels, at its defaults (maps and grids of 512 texels or cells, the reference at 8
samples), judged against stored goldens by statistics rather than by hashes, so that another CPU's
rounding passes and a real change of V fails. ``tests/test_golden.py`` renders them again.

**Deterministic techniques** (the maps, grids and the rest: the same V on every run of one
machine) are judged as ``idiff -fail 0.002 -failpercent 0.25``: a pixel fails when its V differs
from the golden's by more than :data:`FAIL` (half an 8-bit display step) or is not finite; the frame
fails when more than :data:`FAIL_PERCENT` % of its pixels fail (4 of 48 x 36: a few edge pixels
that another CPU's rounding moves across a depth test pass; a shadow edge one pixel over, or a
penumbra 1 % darker, fails).

**Stochastic techniques** (:data:`STOCHASTIC`: the reference and rtdenoise) are judged as Mitsuba
3's render tests judge theirs: the golden is the technique's expected V at high sample count with
its per-pixel variance, and each pixel gets a two-sided Z-test,
``z = |V - mean| / sqrt(max(var, 1e-4) / n + var / N)``, p = erfc(z / sqrt 2). For the reference,
``mean`` and ``var`` (the variance of one light sample, ``V_stderr^2 x N``) come from
:data:`GOLD_SAMPLES` samples, and ``n`` is the frame's 8 samples; for rtdenoise, ``mean`` and ``var``
(the variance of one frame) come from :data:`SEEDS` frames of seeds 1..32, and ``n = 1``; as the
denoiser spreads each ray over its neighbourhood, a pixel's variance is the largest of its 3 x 3
neighbourhood's (one frame's rare outcomes at a pixel, +-0.3 to 0.5 in V where 32 frames never
moved it, come from there: measured on ``plants``, 5 pixels beyond the level without it, none with
it). Where the reference's V is a whole count k of its n samples (an unweighted light: each sample
seen or blocked), p is the exact two-sided binomial tail of k given the golden's V instead: the
normal tail is far too thin there (a pixel whose golden is 0.999 shows 7 of 8 once in 125 frames;
the Z-test put it at |z| 11). A pixel
passes when p > 1 - (1 - 0.01) ^ (1 / pixels) (:data:`ALPHA` Šidák-corrected over the frame's
pixels) and is finite; the frame passes when at least :data:`PASS_FRACTION` of its pixels pass
(at most 4 of 1728 fail).

A failing frame writes its V, the golden, their difference and (stochastic) the z image as PNGs
and one labelled figure under :func:`out_dir` (``$WSOFT_GOLDEN_OUT``, else a ``wsoft-golden``
folder in the temporary directory), and the test's message names the folder.

The goldens live in ``tests/golden/``: ``index.json`` (one line per frame: stage, technique,
parameters, lights, kind, mean V and the golden's sample count) and one ``<technique>.npz`` per
technique (V as uint16 steps of 1/65535; the stochastic ones' variance as float16). Write them
again (after a change that moves frames on purpose, saying why, or to add a technique's frames)
with ``python tests/golden.py --write [--jobs N] [--stages A,B] [TECHNIQUE ...]``: all of them,
or those stages' and techniques' frames only (the others kept), one stage per task on N processes
(default: the CPU count).
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DIR = Path(__file__).with_name("golden")
INDEX = DIR / "index.json"
WIDTH, HEIGHT = 48, 36
STOCHASTIC = ("reference", "rtdenoise")
GOLD_SAMPLES = 1024  # the reference golden's light samples per pixel
SEEDS = 32  # rtdenoise's golden: mean and variance over the frames of seeds 1..SEEDS (the test renders seed 0)
FAIL = 0.002  # deterministic: a pixel fails beyond this |V - golden| (idiff -fail)
FAIL_PERCENT = 0.25  # deterministic: the frame fails when more than this % of its pixels fail (idiff -failpercent)
ALPHA = 0.01  # stochastic: the chance that a frame's pixels hold any false rejection (Šidák over the pixels)
PASS_FRACTION = 0.9975  # stochastic: the share of pixels that must pass
VAR_FLOOR = 1e-4  # stochastic: the smallest variance a pixel's test assumes (Mitsuba's sanitising floor)


def golden_params(cls) -> dict:
    """The parameters a technique's golden frames are rendered with."""
    if cls.name == "reference":
        return {"samples": 8}
    return {cls.size_param: 512} if cls.size_param else {}


def frames(scene_names: list[str] | None = None):
    """(scene, scene name, technique name, parameters) of every golden frame (of ``scene_names``'
    stages only, when given), in a fixed order."""
    from wsoft import usd_scenes
    from wsoft.pipeline import load_stage
    from wsoft.pipeline.build import refusal
    from wsoft.pipeline.loading import too_big_to_flatten
    from wsoft.techniques import TECHNIQUES, bundled_names, create

    for scene_name in scene_names if scene_names is not None else usd_scenes.names():
        scene = load_stage(str(usd_scenes.path(scene_name)))
        for name in bundled_names():
            params = golden_params(TECHNIQUES[name])
            tech = create(name, params)
            if not any(refusal((name, params), scene, light, width=WIDTH, height=HEIGHT) is None for light in scene.lights):
                continue
            if scene.instanced and tech.instancing_why() and too_big_to_flatten(scene):
                continue
            yield scene, scene_name, name, params


def render(scene, name: str, params: dict):
    """One frame at the golden size on the CPU (a stage's own warnings, a light beyond one
    frustum, are not the point here)."""
    import wsoft

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return wsoft.render(scene, name, width=WIDTH, height=HEIGHT, device="cpu", **params)


def kind_of(technique: str) -> str:
    return "stochastic" if technique in STOCHASTIC else "deterministic"


# -- the goldens on disk ------------------------------------------------------------------------------


@dataclass
class Golden:
    """A stored golden frame: V (float32, shape [HEIGHT, WIDTH]); ``var`` and ``n_test`` / ``n_gold``
    for a stochastic one (the variance of one sample, the frame's samples, the golden's)."""

    scene: str
    technique: str
    params: dict
    lights: list
    kind: str
    V: np.ndarray
    var: np.ndarray | None = None
    n_test: int = 1
    n_gold: int = 1


def quantize(v: np.ndarray) -> np.ndarray:
    """V in [0, 1] as uint16 steps of 1/65535 (NaN never stored: the goldens are checked finite)."""
    return np.round(np.clip(np.asarray(v, np.float64), 0.0, 1.0) * 65535.0).astype(np.uint16)


def load_goldens() -> dict[tuple[str, str], Golden]:
    """Every stored golden by (scene, technique)."""
    index = [json.loads(line) for line in INDEX.read_text().splitlines() if line.strip()]
    arrays = {t: np.load(DIR / f"{t}.npz") for t in sorted({r["technique"] for r in index})}
    out = {}
    for r in index:
        a = arrays[r["technique"]]
        var = a[f"{r['scene']}.var"].astype(np.float32) if r["kind"] == "stochastic" else None
        out[(r["scene"], r["technique"])] = Golden(r["scene"], r["technique"], r["params"], r["lights"], r["kind"],
                                                   a[f"{r['scene']}.v"].astype(np.float32) / 65535.0, var, r.get("n_test", 1), r.get("n_gold", 1))
    return out


def make_golden(scene, scene_name: str, name: str, params: dict) -> Golden:
    """Render the golden of one frame: the frame itself (deterministic), the reference at
    :data:`GOLD_SAMPLES` samples (seed 1), or rtdenoise's mean and variance over :data:`SEEDS` seeds."""
    if name == "reference":
        f = render(scene, name, {**params, "samples": GOLD_SAMPLES, "seed": 1})
        var = np.asarray(f.channels["V_stderr"], np.float64) ** 2 * GOLD_SAMPLES
        return Golden(scene_name, name, params, f.stats["lights"], "stochastic", np.asarray(f.V, np.float32), var.astype(np.float32),
                      int(params["samples"]), GOLD_SAMPLES)
    if name in STOCHASTIC:
        vs = []
        for seed in range(1, SEEDS + 1):
            f = render(scene, name, {**params, "seed": seed})
            vs.append(np.asarray(f.V, np.float64))
        from scipy.ndimage import maximum_filter

        stack = np.stack(vs)
        var = maximum_filter(stack.var(0, ddof=1), size=3, mode="nearest")  # a denoised pixel's rare outcomes are its neighbours'
        return Golden(scene_name, name, params, f.stats["lights"], "stochastic", stack.mean(0).astype(np.float32), var.astype(np.float32),
                      1, SEEDS)
    f = render(scene, name, params)
    return Golden(scene_name, name, params, f.stats["lights"], "deterministic", np.asarray(f.V, np.float32))


def stage_goldens(job: tuple[str, list[str] | None]) -> list[Golden]:
    """The goldens of one stage (``job``: its name, and the techniques to render or None for all)."""
    scene_name, techniques = job
    out = []
    for scene, _, name, params in frames([scene_name]):
        if techniques and name not in techniques:
            continue
        g = make_golden(scene, scene_name, name, params)
        bad = int((~np.isfinite(g.V)).sum())
        if bad:
            raise RuntimeError(f"golden {scene_name} {name}: {bad} non-finite pixels in V; fix the frame before storing it")
        out.append(g)
        print(f"  {scene_name} {name}: mean V {float(g.V.mean()):.6f}", file=sys.stderr, flush=True)
    return out


def write_goldens(techniques: list[str] | None = None, jobs: int = 1, stages: list[str] | None = None) -> int:
    """Render and store the goldens (all of them, or only those of ``techniques`` and ``stages``;
    the others stored are kept), one stage per task on ``jobs`` processes; returns how many were
    written. Each stage is stored as soon as it is rendered (merged with what is stored then: an
    interrupted write keeps the stages it finished, a later write of other stages adds to them);
    a write of everything then drops the goldens of stages and techniques no longer rendered."""
    from wsoft import usd_scenes

    tasks = [(name, techniques) for name in (stages or usd_scenes.names())]
    new: dict[tuple[str, str], Golden] = {}
    if jobs > 1:
        import multiprocessing

        with multiprocessing.get_context("spawn").Pool(jobs) as pool:
            for gs in pool.imap_unordered(stage_goldens, tasks, chunksize=1):
                new |= {(g.scene, g.technique): g for g in gs}
                store({(g.scene, g.technique): g for g in gs})
    else:
        for t in tasks:
            gs = stage_goldens(t)
            new |= {(g.scene, g.technique): g for g in gs}
            store({(g.scene, g.technique): g for g in gs})
    if not (techniques or stages):
        store(new, keep=False)
    return len(new)


def store(goldens: dict[tuple[str, str], Golden], keep: bool = True) -> None:
    """Write ``goldens`` (with the stored ones they do not replace when ``keep``) to :data:`DIR`:
    each technique's npz and the index, each written beside and then moved into place."""
    if keep and INDEX.exists():
        goldens = {**load_goldens(), **goldens}
    DIR.mkdir(exist_ok=True)
    by_tech: dict[str, dict[str, np.ndarray]] = {}
    lines = []
    for (scene_name, name), g in sorted(goldens.items()):
        arrays = by_tech.setdefault(name, {})
        arrays[f"{scene_name}.v"] = quantize(g.V)
        if g.kind == "stochastic":
            arrays[f"{scene_name}.var"] = np.asarray(g.var, np.float16)
        row = {"scene": scene_name, "technique": name, "params": g.params, "lights": g.lights, "kind": g.kind,
               "mean_v": round(float(np.mean(g.V)), 6)}
        if g.kind == "stochastic":
            row |= {"n_test": g.n_test, "n_gold": g.n_gold}
        lines.append(json.dumps(row))
    for name, arrays in by_tech.items():
        tmp = DIR / f"{name}.tmp.npz"
        np.savez_compressed(tmp, **arrays)
        tmp.replace(DIR / f"{name}.npz")
    for stale in DIR.glob("*.npz"):
        if stale.stem not in by_tech:
            stale.unlink()
    tmp = INDEX.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(INDEX)


# -- judging a frame -------------------------------------------------------------------------------


@dataclass
class Judgement:
    """A frame against its golden: ``ok``; ``failing`` pixels of ``pixels`` (``allowed`` at most);
    ``rule``: the test in words; ``diff`` (frame - golden) and, stochastic, ``z``."""

    ok: bool
    failing: int
    allowed: int
    pixels: int
    rule: str
    diff: np.ndarray
    z: np.ndarray | None = None


def sidak_level(pixels: int, alpha: float = ALPHA) -> float:
    """Each pixel's level so that a frame of ``pixels`` holds any false rejection with chance ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / pixels)


def z_image(v: np.ndarray, g: Golden) -> np.ndarray:
    """The Z statistic of each pixel of a stochastic frame ``v`` against its golden."""
    var = np.asarray(g.var, np.float64)
    sd = np.sqrt(np.maximum(var, VAR_FLOOR) / g.n_test + var / g.n_gold)
    return np.abs(np.asarray(v, np.float64) - g.V) / sd


def judge(v: np.ndarray, g: Golden) -> Judgement:
    """Judge frame ``v`` (V, shape [HEIGHT, WIDTH]) against golden ``g`` by its kind's rule (module docstring)."""
    from scipy.special import erfc

    v = np.asarray(v, np.float64)
    if v.shape != g.V.shape:
        raise ValueError(f"{g.scene} {g.technique}: frame of shape {v.shape}, golden {g.V.shape}")
    finite = np.isfinite(v)
    diff = np.where(finite, v - g.V, np.nan)
    pixels = v.size
    if g.kind == "stochastic":
        z = z_image(np.where(finite, v, 0.0), g)
        level = sidak_level(pixels)
        p = erfc(z / math.sqrt(2.0))
        counted = binomial_pixels(v, g)
        if counted.any():  # k of n samples visible: the exact binomial tail, where the normal one is far too thin
            p = np.where(counted, binomial_p(v, g), p)
        fail = ~finite | (p <= level)
        allowed = int(math.floor((1.0 - PASS_FRACTION) * pixels + 1e-9))
        rule = (f"Z-test per pixel (an exact binomial test where the reference's V is k of its {g.n_test} samples), "
                f"p <= {level:.3g} (alpha {ALPHA} Sidak-corrected over {pixels} pixels, |z| >= "
                f"{float(np.sqrt(2.0) * _erfcinv(level)):.2f}), at least {PASS_FRACTION:.2%} passing")
        return Judgement(int(fail.sum()) <= allowed, int(fail.sum()), allowed, pixels, rule, diff, np.where(finite, z, np.inf))
    fail = ~finite | (np.abs(np.nan_to_num(diff, nan=0.0)) > FAIL)
    allowed = int(math.floor(FAIL_PERCENT / 100.0 * pixels + 1e-9))
    rule = f"|V - golden| > {FAIL} fails a pixel; more than {FAIL_PERCENT} % failing pixels fail the frame"
    return Judgement(int(fail.sum()) <= allowed, int(fail.sum()), allowed, pixels, rule, diff)


def binomial_pixels(v: np.ndarray, g: Golden) -> np.ndarray:
    """bool [HEIGHT, WIDTH]: the reference's pixels whose V is a whole count of its ``n_test``
    samples (each sample seen or blocked: an unweighted light), where :func:`binomial_p` applies."""
    if g.technique != "reference" or g.n_test < 2:
        return np.zeros(np.shape(v), bool)
    k = np.asarray(v, np.float64) * g.n_test
    return np.isfinite(k) & (np.abs(k - np.round(k)) < 1e-3)


def binomial_p(v: np.ndarray, g: Golden) -> np.ndarray:
    """Two-sided exact binomial p-value of k = V n_test samples seen when each is seen with the
    golden's V: ``min(1, 2 min(P(X <= k), P(X >= k)))``. Stratified samples vary less than
    independent ones, so the test is conservative for them."""
    from scipy.stats import binom

    n = g.n_test
    k = np.round(np.nan_to_num(np.asarray(v, np.float64)) * n)
    q = np.clip(np.asarray(g.V, np.float64), 0.0, 1.0)
    lower, upper = binom.cdf(k, n, q), binom.sf(k - 1, n, q)
    return np.minimum(1.0, 2.0 * np.minimum(lower, upper))


def _erfcinv(p: float) -> float:
    from scipy.special import erfcinv

    return float(erfcinv(p))


def out_dir() -> Path:
    """Where failing frames are written: ``$WSOFT_GOLDEN_OUT``, else ``<tmp>/wsoft-golden``."""
    return Path(os.environ.get("WSOFT_GOLDEN_OUT") or Path(tempfile.gettempdir()) / "wsoft-golden")


def write_failure(v: np.ndarray, g: Golden, j: Judgement, root: Path | None = None) -> Path:
    """Write a failing frame for a person: ``frame.png``, ``golden.png`` (V, 8-bit grey),
    ``diff.png`` (frame - golden), ``z.png`` (stochastic) and ``figure.png`` (all of them labelled,
    with colour bars) in ``<root>/<scene>-<technique>/``; returns the folder."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.io import write_gray_png
    from wsoft.metrics.figures import DIFF_CMAP, FLIP_CMAP

    d = (root or out_dir()) / f"{g.scene}-{g.technique}"
    d.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a NaN pixel is counted in the judgement and shown in the figure
        write_gray_png(str(d / "frame.png"), v)
    write_gray_png(str(d / "golden.png"), g.V)
    lim = max(float(np.nanmax(np.abs(j.diff))) if np.isfinite(j.diff).any() else 0.0, FAIL)
    plt.imsave(d / "diff.png", np.nan_to_num(j.diff, nan=0.0), cmap=DIFF_CMAP, vmin=-lim, vmax=lim)
    panels = [("frame V", v, "gray", 0.0, 1.0), ("golden V", g.V, "gray", 0.0, 1.0), ("frame - golden", j.diff, DIFF_CMAP, -lim, lim)]
    if j.z is not None:
        zcrit = float(np.sqrt(2.0) * _erfcinv(sidak_level(j.pixels)))
        plt.imsave(d / "z.png", np.minimum(np.nan_to_num(j.z, posinf=2 * zcrit), 2 * zcrit), cmap=FLIP_CMAP, vmin=0.0, vmax=2 * zcrit)
        panels.append((f"|z| (fails from {zcrit:.2f})", np.minimum(j.z, 2 * zcrit), FLIP_CMAP, 0.0, 2 * zcrit))
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 2.8), constrained_layout=True)
    for ax, (title, img, cmap, lo, hi) in zip(axes, panels):
        im = ax.imshow(img, cmap=cmap, vmin=lo, vmax=hi, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    fig.suptitle(f"{g.scene} {g.technique}: {j.failing} of {j.pixels} pixels fail (at most {j.allowed})", fontsize=10)
    fig.savefig(d / "figure.png", dpi=100)
    plt.close(fig)
    return d


def check_all(root: Path | None = None) -> tuple[list[str], list[str], list[str], int]:
    """Render every golden frame now and judge it: (failures, each with the folder its images were
    written to; goldens no longer rendered; frames without a golden; frames judged)."""
    goldens = load_goldens()
    failures, seen, new = [], set(), []
    for scene, scene_name, name, params in frames():
        key = (scene_name, name)
        seen.add(key)
        g = goldens.get(key)
        if g is None:
            new.append(f"{scene_name} {name}")
            continue
        v = np.asarray(render(scene, name, params).V, np.float32)
        j = judge(v, g)
        if not j.ok:
            d = write_failure(v, g, j, root)
            failures.append(f"{scene_name} {name}: {j.failing} of {j.pixels} pixels fail ({j.rule}; at most {j.allowed}); "
                            f"mean V {g.V.mean():.5f} -> {np.nanmean(v):.5f}; images in {d}")
    missing = sorted(f"{s} {t}" for s, t in set(goldens) - seen)
    return failures, missing, new, len(seen) - len(new)


def main(argv: list[str]) -> int:
    if not argv or argv[0] != "--write":
        print(__doc__)
        return 2
    from wsoft.techniques import bundled_names

    rest = argv[1:]
    jobs = os.cpu_count() or 1
    if "--jobs" in rest:
        i = rest.index("--jobs")
        try:
            jobs = int(rest[i + 1])
        except (IndexError, ValueError):
            print("golden.py --write: --jobs takes a number of processes", file=sys.stderr)
            return 2
        del rest[i:i + 2]
    stages = None
    if "--stages" in rest:
        from wsoft import usd_scenes

        i = rest.index("--stages")
        stages = rest[i + 1].split(",") if i + 1 < len(rest) else []
        del rest[i:i + 2]
        bad = sorted(set(stages) - set(usd_scenes.names())) or ([] if stages else ["(none given)"])
        if bad:
            print(f"golden.py --write: --stages: not bundled stages: {', '.join(bad)}", file=sys.stderr)
            return 2
    only = rest or None
    unknown = sorted(set(only or []) - set(bundled_names()))
    if unknown:
        print(f"golden.py --write: not bundled techniques: {', '.join(unknown)} (bundled: {', '.join(bundled_names())})", file=sys.stderr)
        return 2
    n = write_goldens(only, max(jobs, 1), stages)
    size = sum(f.stat().st_size for f in DIR.glob("*") if f.is_file())
    print(f"wrote {n} golden frames to {DIR} ({size / 1024:.0f} KiB in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
