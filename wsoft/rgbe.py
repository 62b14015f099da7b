"""Radiance ``.hdr`` (RGBE) images: :func:`read_rgbe` and :func:`write_rgbe`.

The format (Greg Ward's, as Radiance's ``color.c`` and the ``ra_*`` tools read it): a text header
starting ``#?RADIANCE`` (or ``#?RGBE``), lines of ``KEY=value`` (``FORMAT=32-bit_rle_rgbe``; an
``EXPOSURE`` line divides the stored values), an empty line, the resolution line ``-Y H +X W`` (rows
top-down, columns left to right; the other orientations are refused), then the pixels: 4 bytes each
(R, G, B mantissas and a shared exponent E: value = (m + 0.5) / 256 x 2^(E - 128), 0 where E = 0),
each row flat or in the "new" run-length encoding (``2 2 W_hi W_lo``, then each of the 4 components
as runs: a count byte > 128 repeats the next byte count - 128 times, else count literal bytes).
The old RLE (repeat-previous-pixel codes ``1 1 1 n``) is refused.
"""

from __future__ import annotations

import numpy as np


class RgbeError(Exception):
    """A ``.hdr`` file wsoft cannot read; the message says why (one line)."""


def read_rgbe(data: bytes) -> np.ndarray:
    """The image in ``data`` as linear float32 RGB, shape ``[H, W, 3]``, row 0 the top."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise RgbeError("is not a Radiance .hdr file (no #?RADIANCE or #?RGBE signature)")
    pos = 0
    exposure = 1.0
    lines = []
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise RgbeError("ends inside its header")
        line = data[pos:end].strip()
        pos = end + 1
        if not line and lines:
            break
        lines.append(line)
        if line.startswith(b"FORMAT=") and line != b"FORMAT=32-bit_rle_rgbe":
            raise RgbeError(f"has {line.decode('latin-1')} (only FORMAT=32-bit_rle_rgbe is read)")
        if line.startswith(b"EXPOSURE="):
            try:
                exposure *= float(line[9:])
            except ValueError:
                raise RgbeError(f"has a malformed header line {line.decode('latin-1')!r}") from None
    end = data.find(b"\n", pos)
    parts = data[pos:end].split() if end >= 0 else []
    if len(parts) != 4 or parts[0] != b"-Y" or parts[2] != b"+X":
        raise RgbeError(f"has resolution line {data[pos:end if end >= 0 else pos + 40].decode('latin-1')!r}: only '-Y H +X W' "
                        "(rows top-down) is read")
    try:
        h, w = int(parts[1]), int(parts[3])
    except ValueError:
        raise RgbeError("has a malformed resolution line") from None
    if h <= 0 or w <= 0:
        raise RgbeError(f"is {w} x {h} pixels: empty")
    pos = end + 1
    buf = np.frombuffer(data, np.uint8)
    out = np.empty((h, w, 4), np.uint8)
    for y in range(h):
        pos = _read_row(buf, pos, w, out[y])
    mant = out[..., :3].astype(np.float32)
    e = out[..., 3].astype(np.int32)
    scale = np.where(e == 0, 0.0, np.ldexp(1.0, e - 136)).astype(np.float32)  # 2^(E - 128) / 256
    rgb = np.where(e[..., None] == 0, 0.0, (mant + 0.5) * scale[..., None]).astype(np.float32)
    if exposure != 1.0:
        rgb /= np.float32(exposure)
    return rgb


def _read_row(buf: np.ndarray, pos: int, w: int, row: np.ndarray) -> int:
    """One row of ``w`` pixels from ``buf`` at ``pos`` into ``row`` ([w, 4]); returns the position after it."""
    n = len(buf)
    if pos + 4 > n:
        raise RgbeError("ends before its last row of pixels")
    if 8 <= w < 32768 and buf[pos] == 2 and buf[pos + 1] == 2 and not buf[pos + 2] & 0x80:
        if (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) != w:
            raise RgbeError("has a run-length row of the wrong width")
        pos += 4
        for c in range(4):
            x = 0
            while x < w:
                if pos >= n:
                    raise RgbeError("ends inside a run-length row")
                count = int(buf[pos])
                pos += 1
                if count > 128:
                    count -= 128
                    if count > w - x or pos >= n:
                        raise RgbeError("has a run past its row's end")
                    row[x:x + count, c] = buf[pos]
                    pos += 1
                else:
                    if count == 0 or count > w - x or pos + count > n:
                        raise RgbeError("has a literal run past its row's end")
                    row[x:x + count, c] = buf[pos:pos + count]
                    pos += count
                x += count
        return pos
    if pos + 4 * w > n:
        raise RgbeError("ends before its last row of pixels")
    flat = buf[pos:pos + 4 * w].reshape(w, 4)
    if np.any((flat[:, 0] == 1) & (flat[:, 1] == 1) & (flat[:, 2] == 1)):
        raise RgbeError("uses the old run-length encoding (repeat-pixel codes), which is not read")
    row[:] = flat
    return pos + 4 * w


def write_rgbe(path: str, rgb: np.ndarray) -> None:
    """``rgb`` (``[H, W, 3]``, linear, >= 0, row 0 the top) as a flat (unencoded) Radiance ``.hdr`` file."""
    rgb = np.maximum(np.asarray(rgb, np.float64), 0.0)
    h, w = rgb.shape[:2]
    m = rgb.max(axis=2)
    mant, exp = np.frexp(m)  # m = mant 2^exp, mant in [0.5, 1)
    scale = np.where(m > 1e-32, mant * 256.0 / np.where(m > 1e-32, m, 1.0), 0.0)
    px = np.zeros((h, w, 4), np.uint8)
    px[..., :3] = np.clip(np.floor(rgb * scale[..., None]), 0, 255).astype(np.uint8)
    px[..., 3] = np.where(m > 1e-32, np.clip(exp + 128, 0, 255), 0).astype(np.uint8)
    header = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode("ascii")
    with open(path, "wb") as f:
        f.write(header + px.tobytes())

