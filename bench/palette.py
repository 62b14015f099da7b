"""One palette for every report's plots: each technique its own colour and marker, the same in
every figure (the reference black)."""

from __future__ import annotations

# the techniques in a fixed order; a plugin's technique takes the next free style after them
ORDER = ("hard", "pcf", "pcss", "vsm", "esm", "evsm", "msm", "msm_soft", "salzman", "essm", "vssm", "ssm", "izb", "dcs", "pwedge", "rtdenoise")
MARKERS = "osD^vP*Xh<>p"


def style(technique: str) -> dict:
    """``{"color", "marker"}`` of ``technique``: black dots for the reference, else a colour of
    matplotlib's ``tab20`` and a marker, distinct for the first 20 techniques."""
    from matplotlib import colormaps

    if technique == "reference":
        return {"color": "black", "marker": "."}
    i = ORDER.index(technique) if technique in ORDER else len(ORDER) + sum(map(ord, technique)) % 20
    cmap = colormaps["tab20"]
    return {"color": cmap((2 * i) % 20 + (i // 10) % 2), "marker": MARKERS[i % len(MARKERS)]}
