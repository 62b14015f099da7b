"""A comparison as one picture a person reads: :func:`write_compare_grid`.

Each technique of a :func:`wsoft.compare` (or of one frame of a
:func:`wsoft.compare_sequence`) gets a cell of tiles, one above the other: its shaded image as its
PNG shows it (:func:`wsoft.metrics.flip.ldr_image`; ``V`` in grey without a colour); its ꟻLIP map
against the reference (magma, 0 to 1, with a colour bar), where the comparison measured one; and
for every light a row with the signed difference ``V − V_ref`` of that light against the reference
in a diverging colour map (``RdBu_r``: red where the technique is lighter than the reference, blue
where it is darker), with one symmetric limit for every tile and a colour bar. The reference's cell
comes first: its shaded image and each light's ``V`` (grey, 0 to 1). Background pixels (the
reference's ``A`` = 0) are grey in the difference; a pixel whose ``V`` is NaN or inf is drawn in
lime and counted in the tile's title, never hidden. Every cell is framed in the technique's
colour of the one palette (:func:`wsoft.palette.style`).

matplotlib (Agg) is imported at the first call.
"""

from __future__ import annotations

import math
import os
import textwrap

import numpy as np

from wsoft.errors import ParameterError
from wsoft.metrics.flip import has_rgb, ldr_image

DIFF_CMAP = "RdBu_r"
FLIP_CMAP = "magma"  # as the -flip.png maps (wsoft.metrics.flip.magma)
NAN_COLOUR = (0.55, 1.0, 0.0, 1.0)  # lime: a non-finite V
BACKGROUND = "#c8c8c8"  # uncovered pixels in the difference tiles
MIN_LIMIT = 0.05  # the smallest colour-bar limit: reference noise does not fill the scale
TILE_IN = (2.6, 4.2)  # a tile's width in inches: the frame's pixels at the figure's dpi, within these bounds
COLOURBAR_IN = 0.75  # beside each tile, its colour bar
TITLES_IN = 0.9  # above a cell's two tiles, their titles
SUPTITLE_IN = 0.45


def grid_size(cells: int, width: int, height: int, columns: int = 4, dpi: int = 110, tiles: int = 2) -> tuple[float, float, int, int]:
    """The figure of :func:`write_compare_grid`: its size in inches and its columns and rows of
    cells, for ``cells`` cells (the techniques and the reference) of ``tiles`` tiles each (the
    shaded image, the ꟻLIP map where there is one, a difference per light) of ``width`` x
    ``height`` frames: at most ``columns`` to a row, the rows as even as they can be (5 cells: 3 and 2)."""
    nrow = math.ceil(max(1, cells) / max(1, columns))
    ncol = math.ceil(max(1, cells) / nrow)
    tile_w = min(TILE_IN[1], max(TILE_IN[0], width / dpi))
    return ncol * (tile_w + COLOURBAR_IN), nrow * (tiles * tile_w * height / width + TITLES_IN * tiles / 2) + SUPTITLE_IN, ncol, nrow


def short_params(technique: str, params: dict) -> str:
    """The parameters of ``technique`` that differ from its defaults, ``shadow_map_size=512,
    filter_samples=16`` (``defaults`` when none does; every parameter for a technique that is not
    installed)."""
    try:
        from wsoft.techniques import get_technique

        defaults = get_technique(technique).defaults()
    except Exception:  # noqa: BLE001  (a technique of another installation: show what the stats hold)
        defaults = {}
    changed = {k: v for k, v in params.items() if k not in defaults or not _same(v, defaults[k])}
    return ", ".join(f"{k}={_fmt(v)}" for k, v in changed.items()) or "defaults"


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def tile_title(technique: str, params: dict, frame_ms: float | None, error: dict | None, width: int = 44) -> str:
    """The title of a cell: the technique and its short parameters (wrapped at ``width``
    characters), then its frame time and its error against the reference (penumbra MAE and MAE)."""
    if technique == "reference" and "samples" in params:  # its sample count, always
        rest = short_params(technique, {k: v for k, v in params.items() if k != "samples"})
        text = f"{params['samples']} samples" + (f", {rest}" if rest != "defaults" else "")
    else:
        text = short_params(technique, params)
    head = textwrap.wrap(f"{technique} ({text})", width, break_on_hyphens=False) or [technique]
    nums = [] if frame_ms is None else [f"{frame_ms:.1f} ms"]
    if error is not None:
        nums.append(f"penumbra MAE {error['mae_penumbra']:.4f}, MAE {error['mae']:.4f}")
        if error.get("nan_pixels"):
            nums.append(f"NaN {error['nan_pixels']} px")
    return "\n".join(head + ([", ".join(nums)] if nums else []))


def _v(light: str | None) -> str:
    return "V" if light is None else f"V.{light}"


def _shaded(channels: dict) -> tuple[np.ndarray, str | None]:
    """The shaded image (RGB in [0, 1]) and None, or V in grey and the colour map for it."""
    if has_rgb(channels):
        return ldr_image(channels), None
    return np.clip(np.nan_to_num(np.asarray(channels["V"], np.float32)), 0.0, 1.0), "gray"


def _reference_channels(frames, reference) -> tuple[dict, dict]:
    """The reference's channels (``V.<light>``, ``A``, ``R G B`` where it has them) and its tile's
    description: a frame of ``frames`` (``stats["reference"]``) or a GroundTruth handed in."""
    if reference is None:
        label = frames.stats.get("reference")
        if label is None or label not in frames:
            raise ParameterError("write_compare_grid: the frames hold no reference frame (they were compared against a ground truth); "
                                 "pass that GroundTruth as reference=")
        fr = frames[label]
        return fr.channels, {"technique": "reference", "label": label, "params": fr.stats["params"],
                             "ms": fr.stats["timings_ms"]["total"]}
    ch = {f"V.{ll}": g["V"] for ll, g in reference.lights.items()}
    ch["A"] = next(iter(reference.lights.values()))["A"]
    ch["V"] = next(iter(reference.lights.values()))["V"]
    if reference.shaded is not None:
        ch.update(reference.shaded)
    return ch, {"technique": "reference", "label": "reference", "params": {"samples": reference.samples}, "ms": None}


def write_compare_grid(path: str, frames, reference=None, *, reference_ms: float | None = None, title: str | None = None, columns: int = 4,
                       dpi: int = 110) -> dict[str, str]:
    """Write the comparison of ``frames`` (a :class:`~wsoft.pipeline.FrameSet` from
    :func:`wsoft.compare`, each technique carrying ``stats["error"]``) as one PNG at ``path``.

    ``reference``: the :class:`~wsoft.metrics.GroundTruth` the frames were measured against, when
    they hold no reference frame (``compare(ground_truth=...)``, a frame of
    :func:`wsoft.compare_sequence`, its ``ground_truths[i]``), with ``reference_ms`` its time if
    known; by default the reference is the frame ``stats["reference"]`` names. The cells (see the
    module) run ``columns`` to a row, the reference first (:func:`grid_size`); ``title`` goes
    above them (default: the stage, the frame size and the device).

    Returns ``{label: title}``: each cell's title as drawn (technique, short parameters, frame ms,
    penumbra MAE and MAE), the reference's under its label."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.cm
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    from wsoft.palette import style

    ref_ch, ref_info = _reference_channels(frames, reference)
    if reference is not None:
        ref_info["ms"] = reference_ms
    labels = [l for l in frames if reference is not None or l != ref_info["label"]]
    cover = np.asarray(ref_ch["A"]) > 0
    # every light of any technique that the reference has, in order: a row of tiles each
    lights = [ll for ll in dict.fromkeys(ll for l in labels for ll in frames[l].stats["light_labels"]) if f"V.{ll}" in ref_ch]
    if not lights:
        lights = [None]  # frames without per-light channels: V itself
    has_flip = any("flip" in getattr(frames[l], "error_maps", {}) for l in labels)
    shaded, scmap = _shaded(ref_ch)
    cells = [{"label": ref_info["label"], "technique": "reference", "title": tile_title("reference", ref_info["params"], ref_info["ms"], None),
              "shaded": shaded, "cmap": scmap, "v": {ll: np.asarray(ref_ch[_v(ll)], np.float64) for ll in lights}}]
    for label in labels:
        st = frames[label].stats
        shaded, scmap = _shaded(frames[label].channels)
        errors = st.get("errors") or ({lights[0]: st["error"]} if st.get("error") else {})
        cells.append({"label": label, "technique": st["technique"],
                      "title": tile_title(st["technique"], st["params"], st["timings_ms"]["total"], st.get("error")),
                      "shaded": shaded, "cmap": scmap, "errors": errors, "flip": getattr(frames[label], "error_maps", {}).get("flip"),
                      "diff": {ll: np.asarray(frames[label][_v(ll)], np.float64) - np.asarray(ref_ch[_v(ll)], np.float64)
                               for ll in lights if _v(ll) in frames[label].channels}})

    # one symmetric limit for every difference: the largest 99.5th percentile of |d| on covered pixels
    lim, absmax = MIN_LIMIT, 0.0
    for c in cells[1:]:
        for diff in c["diff"].values():
            d = np.abs(diff[cover & np.isfinite(diff)])
            if d.size:
                lim = max(lim, float(np.percentile(d, 99.5)))
                absmax = max(absmax, float(d.max()))
    lim = min(1.0, lim)

    h, w = cover.shape
    tiles = 1 + has_flip + len(lights)
    fig_w, fig_h, ncol, nrow = grid_size(len(cells), w, h, columns, dpi, tiles=tiles)
    fig = plt.figure(figsize=(fig_w, fig_h), dpi=dpi, layout="constrained")
    subfigs = np.atleast_1d(fig.subfigures(nrow, ncol, wspace=0.02, hspace=0.02)).reshape(nrow, ncol)
    diff_cmap = matplotlib.colormaps[DIFF_CMAP].with_extremes(bad=BACKGROUND)
    grey = matplotlib.colormaps["gray"].with_extremes(bad=BACKGROUND)
    interp = "nearest" if w <= 320 else "antialiased"
    titles = {}
    any_bad = False
    several = len(lights) > 1
    for k, sf in enumerate(subfigs.flat):
        if k >= len(cells):
            sf.set_visible(False)
            continue
        c = cells[k]
        titles[c["label"]] = c["title"]
        axes = list(np.atleast_1d(sf.subplots(tiles, 1)))
        top = axes.pop(0)
        top.imshow(c["shaded"], cmap=c["cmap"], vmin=0.0, vmax=1.0, interpolation=interp)
        top.set_title(c["title"], fontsize=8, loc="left")
        spacer = sf.colorbar(matplotlib.cm.ScalarMappable(cmap=grey), ax=top, fraction=0.05, pad=0.02)  # the tiles line up
        spacer.ax.set_visible(False)
        drawn = [top]
        if has_flip:
            ax = axes.pop(0)
            drawn.append(ax)
            if c.get("flip") is not None:
                f = np.asarray(c["flip"], np.float32)
                im = ax.imshow(f, cmap=FLIP_CMAP, vmin=0.0, vmax=1.0, interpolation=interp)
                ax.set_title(f"ꟻLIP against the reference (mean {float(np.nanmean(f)):.4f})", fontsize=7)
                cb = sf.colorbar(im, ax=ax, fraction=0.05, pad=0.02, ticks=[0.0, 0.25, 0.5, 0.75, 1.0])
                cb.set_label("ꟻLIP (0: alike)", fontsize=6)
                cb.ax.tick_params(labelsize=6)
            else:  # the reference, or a technique without a ꟻLIP map: an empty tile keeps the rows aligned
                ax.set_visible(False)
                blank = sf.colorbar(matplotlib.cm.ScalarMappable(cmap=grey), ax=ax, fraction=0.05, pad=0.02)
                blank.ax.set_visible(False)
        for ll, ax in zip(lights, axes):
            drawn.append(ax)
            name = f" ({ll})" if several and ll is not None else ""
            if "diff" not in c:  # the reference: its V
                im = ax.imshow(np.where(cover, np.nan_to_num(c["v"][ll]), np.nan), cmap=grey, vmin=0.0, vmax=1.0, interpolation=interp)
                ax.set_title("reference V" + name, fontsize=7)
                cb = sf.colorbar(im, ax=ax, fraction=0.05, pad=0.02)
            elif ll not in c["diff"]:
                ax.set_xticks([])
                ax.set_yticks([])
                ax.text(0.5, 0.5, f"no V for {ll}", ha="center", va="center", fontsize=7, transform=ax.transAxes)
                cb = sf.colorbar(matplotlib.cm.ScalarMappable(cmap=grey), ax=ax, fraction=0.05, pad=0.02)
                cb.ax.set_visible(False)
            else:
                d = c["diff"][ll]
                im = ax.imshow(np.ma.masked_invalid(np.where(cover, d, np.nan)), cmap=diff_cmap, norm=Normalize(-lim, lim), interpolation=interp)
                bad = cover & ~np.isfinite(d)
                if bad.any():
                    any_bad = True
                    overlay = np.zeros((h, w, 4), np.float32)
                    overlay[bad] = NAN_COLOUR
                    ax.imshow(overlay, interpolation="nearest")
                e = c["errors"].get(ll)
                ax.set_title("V − reference V" + name + (f": penumbra MAE {e['mae_penumbra']:.4f}" if several and e else ""), fontsize=7)
                cb = sf.colorbar(im, ax=ax, fraction=0.05, pad=0.02, extend="both" if absmax > lim else "neither")
            cb.ax.tick_params(labelsize=6)
        colour = style(c["technique"])["color"]
        for ax in drawn:
            ax.set_xticks([])
            ax.set_yticks([])
            for sp in ax.spines.values():
                sp.set_edgecolor(colour)
                sp.set_linewidth(1.0 if c["technique"] == "reference" else 2.5)
    if title is None:
        st0 = frames[labels[0]].stats if labels else {}
        stage = os.path.splitext(os.path.basename(st0.get("scene", {}).get("path") or "stage"))[0]
        title = f"{stage}: {st0.get('width', w)}x{st0.get('height', h)}, {st0.get('device', '')}"
    fig.suptitle(f"{title}\nred: lighter than the reference, blue: darker; grey: background" + ("; lime: V not finite" if any_bad else "")
                 + f"; colour limit ±{lim:.2f}" + (f" (largest |difference| {absmax:.2f})" if absmax > lim else ""), fontsize=8)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return titles
