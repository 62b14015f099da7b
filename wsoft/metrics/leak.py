"""Light leaking into umbrae: the failure that filtered shadow maps built on few moments show under
stacked occluders (``vsm``'s light bleeding), measured against the reference.

:func:`umbra_leak` is the arithmetic: of the covered pixels where the reference sees none of the
light (V == 0: every light sample blocked), the fraction a technique lights above ``threshold``
(0.2). :func:`measure_leak` renders techniques and the reference in one frame graph and measures
each (``wsoft.stages.moment_cases.stacked_plates`` is the stage made for it). A NaN in a
technique's image counts as leaked, never dropped.
"""

from __future__ import annotations

import numpy as np

LEAK_THRESHOLD = 0.2


def umbra_leak(v: np.ndarray, ref: np.ndarray, coverage: np.ndarray, threshold: float = LEAK_THRESHOLD) -> dict:
    """{umbra_pixels, leaked_pixels, leak}: the covered pixels (``coverage`` > 0) where ``ref`` is 0,
    those of them where ``v`` is above ``threshold`` (or not finite), and their fraction (0 when
    there is no umbra)."""
    umbra = (np.asarray(coverage) > 0) & (np.asarray(ref) == 0.0)
    vals = np.asarray(v)[umbra]
    leaked = int(np.count_nonzero(~np.isfinite(vals) | (vals > threshold)))
    n = int(umbra.sum())
    return {"umbra_pixels": n, "leaked_pixels": leaked, "leak": leaked / n if n else 0.0}


def measure_leak(scene, techniques, *, width: int = 96, height: int = 72, samples: int = 256, device: str | None = None,
                 light=None, threshold: float = LEAK_THRESHOLD) -> dict[str, dict]:
    """Render ``techniques`` (as :func:`wsoft.render` takes a list: names, or (name, params)) and the
    reference with ``samples`` light samples in one graph; per technique label its
    :func:`umbra_leak` against the reference on the selected light's ``V``."""
    from wsoft.metrics import compare

    fs = compare(scene, techniques, samples=samples, width=width, height=height, device=device, light=light)
    ref = fs[fs.stats["reference"]]
    out = {}
    for label in fs:
        if label == fs.stats["reference"]:
            continue
        out[label] = umbra_leak(fs[label].V, ref.V, ref["A"], threshold)
    return out
