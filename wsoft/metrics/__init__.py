"""Error of a visibility image against the reference, on the same (covered) pixels."""

from __future__ import annotations

import numpy as np

PENUMBRA_LO = 0.01
PENUMBRA_HI = 0.99


def visibility_error(v: np.ndarray, ref: np.ndarray, ref_stderr: np.ndarray | None = None, coverage: np.ndarray | None = None) -> dict:
    """MAE, RMSE, max, MAE in the penumbra and the fraction of pixels outside 3 reference stderr.

    Pixels count where ``coverage > 0`` (background is excluded). The penumbra is where the
    reference is strictly between 0.01 and 0.99.
    """
    v = np.asarray(v, np.float64)
    ref = np.asarray(ref, np.float64)
    if v.shape != ref.shape:
        raise ValueError(f"image {v.shape} and reference {ref.shape} differ in size")
    mask = np.ones(v.shape, bool) if coverage is None else np.asarray(coverage) > 0
    n = int(mask.sum())
    if n == 0:
        return {"pixels": 0, "mae": 0.0, "rmse": 0.0, "max": 0.0, "mae_penumbra": 0.0, "penumbra_pixels": 0, "frac_outside_3se": 0.0}
    d = np.abs(v - ref)[mask]
    pen = ((ref > PENUMBRA_LO) & (ref < PENUMBRA_HI))[mask]
    out = {
        "pixels": n,
        "mae": float(d.mean()),
        "rmse": float(np.sqrt((d * d).mean())),
        "max": float(d.max()),
        "mae_penumbra": float(d[pen].mean()) if pen.any() else 0.0,
        "penumbra_pixels": int(pen.sum()),
    }
    if ref_stderr is not None:
        se = np.asarray(ref_stderr, np.float64)[mask]
        out["frac_outside_3se"] = float(np.mean(d > 3.0 * se))
    return out
