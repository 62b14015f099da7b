"""One palette for every figure: each technique its own colour and marker, the same in the
sweeps' plots (``wsoft.bench``) and in ``wsoft compare``'s grid (the reference black)."""

from __future__ import annotations

# the bundled techniques in a fixed order; a plugin's technique takes one of the styles after them
ORDER = ("hard", "pcf", "pcss", "vsm", "esm", "evsm", "msm", "msm_soft", "salzman", "essm", "vssm", "ssm", "izb", "dcs", "pwedge", "rtdenoise", "csm", "vsmap", "smrt", "gtao", "skymaps")
MARKERS = "osD^vP*Xh<>p"
COLOURS = 40  # tab20 and tab20b


def style(technique: str) -> dict:
    """``{"color", "marker"}`` of ``technique``: black dots for the reference, else a colour of
    matplotlib's ``tab20`` then ``tab20b`` (40 colours) and a marker. The bundled techniques
    (:data:`ORDER`) each have their own colour; a plugin's takes one of the colours left over,
    chosen by its name."""
    from matplotlib import colormaps

    if technique == "reference":
        return {"color": "black", "marker": "."}
    i = ORDER.index(technique) if technique in ORDER else len(ORDER) + sum(map(ord, technique)) % (COLOURS - len(ORDER))
    cmap = colormaps["tab20" if i < 20 else "tab20b"]
    j = i % 20
    return {"color": cmap((2 * j) % 20 + (j // 10) % 2), "marker": MARKERS[i % len(MARKERS)]}


# how a technique's k-th variant (a swept parameter, another light or device) shifts its colour:
# < 0 towards black, > 0 towards white, in this order
_SHADES = (0.0, -0.45, 0.45, -0.25, 0.25, -0.65, 0.65, -0.12, 0.12, -0.55, 0.55, -0.35, 0.35)


def variant_style(technique: str, k: int) -> dict:
    """``{"color", "marker"}`` of the ``k``-th variant of ``technique`` in one figure (several lines
    of one technique: a parameter swept apart, ESSM's ``H`` beside its ``c``): variant 0 is
    :func:`style`, the others keep its hue, darker or lighter, each with the next marker."""
    from matplotlib.colors import to_rgb

    base = style(technique)
    if k == 0:
        return base
    f = _SHADES[k % len(_SHADES)]
    rgb = [c * (1.0 + f) if f < 0 else c + (1.0 - c) * f for c in to_rgb(base["color"])]
    if technique == "reference":  # black: variants in greys
        rgb = [0.12 * k % 0.7] * 3
    marker = MARKERS[(MARKERS.index(base["marker"]) + k) % len(MARKERS)] if base["marker"] in MARKERS else MARKERS[k % len(MARKERS)]
    return {"color": tuple(rgb), "marker": marker}
