"""Writing frames: EXR (OpenEXR, float32 channels) and PNG (Pillow)."""

from __future__ import annotations

import os

import numpy as np


def nonfinite_counts(channels: dict[str, np.ndarray]) -> dict[str, int]:
    """Channel name -> number of NaN or inf values, for the channels that have any."""
    out = {}
    for name, arr in channels.items():
        n = int(np.count_nonzero(~np.isfinite(np.asarray(arr, np.float32))))
        if n:
            out[name] = n
    return out


def write_exr(path: str, channels: dict[str, np.ndarray]) -> dict[str, int]:
    """Write float32 channels to an EXR file. NaN/inf values are never hidden: they are counted
    per channel, reported with a :class:`~wsoft.errors.NonFiniteWarning` and written as 0.
    Returns the counts (channel -> non-finite values)."""
    import warnings

    import OpenEXR

    from wsoft.errors import NonFiniteWarning

    data = {}
    bad = nonfinite_counts({k: v for k, v in channels.items() if not k.startswith("_")})
    if bad:
        warnings.warn(f"{path}: non-finite values written as 0: " + ", ".join(f"{k} {n}" for k, n in bad.items()), NonFiniteWarning, stacklevel=2)
    for name, arr in channels.items():
        if name.startswith("_"):
            continue
        a = np.ascontiguousarray(np.nan_to_num(np.asarray(arr, np.float32), nan=0.0, posinf=0.0, neginf=0.0))
        data[name] = a
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with OpenEXR.File(header, data) as f:
        f.write(path)
    return bad


def read_exr(path: str) -> dict[str, np.ndarray]:
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        return {k: np.array(v.pixels) for k, v in f.channels().items()}


def to_srgb8(x: np.ndarray) -> np.ndarray:
    x = np.clip(np.nan_to_num(x), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


def write_png(path: str, channels: dict[str, np.ndarray]) -> None:
    """PNG of the shaded image (R G B), or of ``V`` when there is no colour."""
    from PIL import Image

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    if all(c in channels for c in "RGB"):
        img = np.stack([to_srgb8(channels[c]) for c in "RGB"], -1)
        Image.fromarray(img, "RGB").save(path)
    else:
        Image.fromarray(to_srgb8(channels["V"]), "L").save(path)


def write_gray_png(path: str, v: np.ndarray, bits: int = 8) -> dict[str, int]:
    """A single channel in [0, 1] as an 8- or 16-bit grey PNG (linear, no gamma). NaN/inf values
    are counted, reported with a :class:`~wsoft.errors.NonFiniteWarning` and written as 0; returns
    the count ({"V": n} when there are any)."""
    import warnings

    from PIL import Image

    from wsoft.errors import NonFiniteWarning

    bad = nonfinite_counts({"V": v})
    if bad:
        warnings.warn(f"{path}: non-finite values written as 0: V {bad['V']}", NonFiniteWarning, stacklevel=2)
    x = np.clip(np.nan_to_num(np.asarray(v, np.float32), nan=0.0, posinf=0.0, neginf=0.0), 0, 1)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    if bits == 16:
        Image.fromarray((x * 65535 + 0.5).astype(np.uint16)).save(path)
    else:
        Image.fromarray((x * 255 + 0.5).astype(np.uint8), "L").save(path)
    return bad
