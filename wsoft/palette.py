"""One palette for every figure: each technique its own colour and marker, the same in the
sweeps' plots (``wsoft.bench``) and in ``wsoft compare``'s grid (the reference black)."""

from __future__ import annotations

# the bundled techniques in a fixed order; a plugin's technique takes one of the styles after them
ORDER = ("hard", "pcf", "pcss", "vsm", "esm", "evsm", "msm", "msm_soft", "salzman", "essm", "vssm", "ssm", "izb", "dcs", "pwedge", "rtdenoise")
MARKERS = "osD^vP*Xh<>p"


def style(technique: str) -> dict:
    """``{"color", "marker"}`` of ``technique``: black dots for the reference, else a colour of
    matplotlib's ``tab20`` and a marker. The bundled techniques (:data:`ORDER`) each have their own
    colour; a plugin's takes one of the colours left over, chosen by its name."""
    from matplotlib import colormaps

    if technique == "reference":
        return {"color": "black", "marker": "."}
    i = ORDER.index(technique) if technique in ORDER else len(ORDER) + sum(map(ord, technique)) % (20 - len(ORDER))
    cmap = colormaps["tab20"]
    return {"color": cmap((2 * i) % 20 + (i // 10) % 2), "marker": MARKERS[i % len(MARKERS)]}
