"""The golden frames (``tests/golden.py``) render as they were written: every bundled technique on
every bundled stage it supports. In the full mode (``-m slow``: about 4 minutes on 2 cores)."""

from __future__ import annotations

import json

import pytest
from golden import FILE, HEIGHT, WIDTH, render_all

pytestmark = pytest.mark.slow


def test_golden_frames_do_not_move():
    """Each frame's V is the one written, bit for bit; a frame of a technique or stage added since
    has no golden value yet and is named (``python tests/golden.py --write`` adds it)."""
    golden = {(r["scene"], r["technique"]): r for r in json.loads(FILE.read_text())}
    now = render_all()
    assert len(golden) >= 270 and len(now) >= len(golden)
    moved = [f"{r['scene']} {r['technique']}: mean V {golden[(r['scene'], r['technique'])]['mean_v']:.6f} -> {r['mean_v']:.6f}"
             for r in now if (r["scene"], r["technique"]) in golden and r["v_sha256"] != golden[(r["scene"], r["technique"])]["v_sha256"]]
    missing = sorted(set(golden) - {(r["scene"], r["technique"]) for r in now})
    new = sorted({(r["scene"], r["technique"]) for r in now} - set(golden))
    assert not moved and not missing, (f"{len(moved)} of {len(golden)} golden frames ({WIDTH}x{HEIGHT}) moved: " + "; ".join(moved)
                                       + (f"; no longer rendered: {missing}" if missing else ""))
    assert not new, f"frames without a golden value (add them with python tests/golden.py --write): {new}"
