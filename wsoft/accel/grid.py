"""Salzman's coarse grid: caster bounding squares marked on a G x G grid over the shadow map,
each row a bit vector, merged by run length into rectangles where the blur runs; the same grid
rejects receivers outside every caster's influence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CasterGrid:
    size: int  # cells per side
    rows: list[int]  # bit vector per row of cells (bit x = cell x is marked)
    rects: list[tuple[int, int, int, int]]  # merged rectangles in cells: x0, x1, y0, y1 (inclusive)
    cell_w: int  # texels per cell, x
    cell_h: int  # texels per cell, y

    def marked(self) -> np.ndarray:
        """[G, G] bool: which cells are marked."""
        out = np.zeros((self.size, self.size), bool)
        for y, bits in enumerate(self.rows):
            for x in range(self.size):
                if bits >> x & 1:
                    out[y, x] = True
        return out

    def texels(self, width: int, height: int) -> np.ndarray:
        """Flat indices of the map's texels inside the rectangles (each once)."""
        parts = []
        for x0, x1, y0, y1 in self.rects:
            tx0, tx1 = x0 * self.cell_w, min((x1 + 1) * self.cell_w, width)
            ty0, ty1 = y0 * self.cell_h, min((y1 + 1) * self.cell_h, height)
            ys, xs = np.mgrid[ty0:ty1, tx0:tx1]
            parts.append((ys * width + xs).ravel())
        return np.concatenate(parts).astype(np.int32) if parts else np.zeros(0, np.int32)


def build_grid(squares: list[tuple[float, float, float, float]], width: int, height: int, size: int) -> CasterGrid:
    """Mark the cells under each bounding square (x0, x1, y0, y1 in texels, already grown by the
    blur radius), keep each row as a bit vector, and merge runs of marked cells that repeat on
    consecutive rows into rectangles."""
    cw, ch = max(1, -(-width // size)), max(1, -(-height // size))
    rows = [0] * size
    for x0, x1, y0, y1 in squares:
        cx0, cx1 = max(int(np.floor(x0 / cw)), 0), min(int(np.floor(x1 / cw)), size - 1)
        cy0, cy1 = max(int(np.floor(y0 / ch)), 0), min(int(np.floor(y1 / ch)), size - 1)
        if cx0 > cx1 or cy0 > cy1:
            continue
        run = ((1 << (cx1 - cx0 + 1)) - 1) << cx0
        for y in range(cy0, cy1 + 1):
            rows[y] |= run
    rects: list[tuple[int, int, int, int]] = []
    open_runs: dict[tuple[int, int], int] = {}  # (x0, x1) -> first row
    for y in range(size + 1):
        runs = set(_runs(rows[y], size)) if y < size else set()
        for run in list(open_runs):
            if run not in runs:
                rects.append((run[0], run[1], open_runs.pop(run), y - 1))
        for run in runs:
            open_runs.setdefault(run, y)
    return CasterGrid(size=size, rows=rows, rects=sorted(rects, key=lambda r: (r[2], r[0])), cell_w=cw, cell_h=ch)


def _runs(bits: int, size: int) -> list[tuple[int, int]]:
    out, x = [], 0
    while x < size:
        if bits >> x & 1:
            s = x
            while x + 1 < size and bits >> (x + 1) & 1:
                x += 1
            out.append((s, x))
        x += 1
    return out
