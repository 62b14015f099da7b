"""The golden frames (``tests/golden.py``): every bundled technique on every bundled stage it
supports, judged against stored goldens by statistics (deterministic frames: a per-pixel
tolerance and a failing-pixel fraction; stochastic ones: a per-pixel Z-test with Šidák
correction). Rendering them all is the full mode (``-m slow``: about 4 minutes on 2 cores); the
test's power, on synthetic changes of the stored goldens, and its bad inputs are quick."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from golden import (DIR, FAIL, FAIL_PERCENT, HEIGHT, INDEX, WIDTH, Golden, check_all, judge, load_goldens, main, out_dir, sidak_level,
                    write_failure)


@pytest.fixture(scope="module")
def goldens() -> dict:
    return load_goldens()


def kind(goldens, k: str) -> list[Golden]:
    return [g for g in goldens.values() if g.kind == k]


def shifted(v: np.ndarray, axis: int) -> np.ndarray:
    """``v`` moved one pixel along ``axis`` (the first row or column repeated, nothing wraps)."""
    out = np.array(v, copy=True)
    if axis == 1:
        out[:, 1:] = v[:, :-1]
    else:
        out[1:, :] = v[:-1, :]
    return out


def few_ulps(v: np.ndarray, seed: int, ulps: int = 4) -> np.ndarray:
    """``v`` in float32 with each pixel moved by up to ``ulps`` units in the last place, at random."""
    rng = np.random.default_rng(seed)
    x = np.asarray(v, np.float32)
    return (x + rng.integers(-ulps, ulps + 1, x.shape).astype(np.float32) * np.spacing(x)).astype(np.float32)


def test_goldens_are_stored_small_and_committed(goldens):
    assert len(goldens) >= 100 and {g.kind for g in goldens.values()} == {"deterministic", "stochastic"}
    assert {g.technique for g in kind(goldens, "stochastic")} == {"reference", "rtdenoise"}
    files = sorted(p for p in DIR.iterdir() if p.is_file())
    assert INDEX in files and all(p.suffix in (".npz", ".json") for p in files)  # no EXR
    assert sum(p.stat().st_size for p in files) <= 2 * 1024 * 1024
    ignored = subprocess.run(["git", "check-ignore", *map(str, files)], capture_output=True, text=True, cwd=DIR.parent.parent)
    assert ignored.stdout.strip() == "", f"ignored by .gitignore: {ignored.stdout}"
    for g in goldens.values():
        assert g.V.shape == (HEIGHT, WIDTH) and np.isfinite(g.V).all()
        if g.kind == "stochastic":
            assert g.var.shape == g.V.shape and (g.var >= 0).all() and g.n_gold > g.n_test


def test_few_ulps_of_float32_noise_pass(goldens):
    """Another CPU's rounding: every golden frame with a few ulps of noise in every pixel passes."""
    for i, g in enumerate(goldens.values()):
        j = judge(few_ulps(g.V, i), g)
        assert j.ok and j.failing == 0, f"{g.scene} {g.technique}: {j.failing} pixels fail"


def test_one_texel_shift_of_a_shadow_edge_fails(goldens):
    """A frame with a shadow edge across the shift (at least 5 pixel pairs that differ by more than
    0.2 along it) fails when its V moves one pixel, in x or in y: every deterministic one; of the
    stochastic ones, whose edges are soft and whose tolerance is their noise, most (a share that
    docs/ci.md states)."""
    tried = {"deterministic": 0, "stochastic": 0}
    caught = dict(tried)
    for g in goldens.values():
        for axis in (0, 1):
            if (np.abs(np.diff(g.V, axis=axis)) > 0.2).sum() < 5:
                continue
            tried[g.kind] += 1
            j = judge(shifted(g.V, axis), g)
            caught[g.kind] += not j.ok
            assert g.kind == "stochastic" or not j.ok, f"{g.scene} {g.technique} shifted along axis {axis}: only {j.failing} pixels fail"
    assert tried["deterministic"] >= len(kind(goldens, "deterministic")) and tried["stochastic"] >= 10, tried
    assert caught["stochastic"] >= 0.85 * tried["stochastic"], (caught, tried)


def test_penumbra_one_percent_darker_fails(goldens):
    """V times 0.99 in the penumbra (0 < V < 1) of a deterministic frame fails wherever the penumbra
    holds more pixels than the rule forgives above V = 0.2 (where 1 % of V exceeds the per-pixel
    tolerance): most frames with a penumbra."""
    allowed = int(FAIL_PERCENT / 100 * WIDTH * HEIGHT)
    with_penumbra = caught = 0
    for g in kind(goldens, "deterministic"):
        pen = (g.V > 0.02) & (g.V < 0.98)
        if pen.sum() < 5:
            continue
        with_penumbra += 1
        j = judge(np.where(pen, g.V * np.float32(0.99), g.V), g)
        wide = int((pen & (g.V * 0.01 > FAIL)).sum())
        assert (not j.ok) == (wide > allowed), f"{g.scene} {g.technique}: {j.failing} fail, {wide} penumbra pixels above V = 0.2"
        caught += not j.ok
    assert with_penumbra >= 0.8 * len(kind(goldens, "deterministic")) and caught >= 0.9 * with_penumbra, (caught, with_penumbra)


def test_stochastic_frames_fail_a_shift_beyond_their_noise(goldens):
    """The Z-test's power on the stochastic goldens: the reference's penumbra at half its V (beyond
    an 8-sample frame's noise, sqrt(0.25 / 8) = 0.18 in V at V = 0.5, per pixel) fails where it
    holds 100 pixels or more (12 of 13 frames on 30 stages); 1 % darker passes everywhere (far below that noise: a per-pixel test
    of one 8-sample frame cannot see it; 20 % darker passed too on 14 stages)."""
    caught = tried = 0
    for g in kind(goldens, "stochastic"):
        pen = (g.V > 0.02) & (g.V < 0.98)
        assert judge(np.where(pen, g.V * np.float32(0.99), g.V), g).ok
        if g.technique == "reference" and pen.sum() >= 100:
            tried += 1
            caught += not judge(np.where(pen, g.V * np.float32(0.5), g.V), g).ok
    assert tried >= 5 and caught >= 0.9 * tried, (caught, tried)


def test_rule_edges_and_bad_frames(goldens, tmp_path):
    g = next(g for g in kind(goldens, "deterministic") if (g.V < 0.98).sum() > 10)
    allowed = int(FAIL_PERCENT / 100 * g.V.size)
    idx = np.flatnonzero(g.V.ravel() < 0.98)
    for n, ok in ((allowed, True), (allowed + 1, False)):
        v = g.V.copy().ravel()
        v[idx[:n]] += 2 * FAIL
        assert judge(v.reshape(g.V.shape), g).ok is ok
    v = g.V.copy()
    v.ravel()[idx[0]] += 0.9 * FAIL  # inside the tolerance
    assert judge(v, g).failing == 0
    v = g.V.copy()
    v.ravel()[idx[: allowed + 1]] = np.nan  # NaN pixels fail, never hidden
    j = judge(v, g)
    assert not j.ok and j.failing == allowed + 1
    with pytest.raises(ValueError, match=f"{g.scene} {g.technique}: frame of shape"):
        judge(v[:, :-1], g)
    s = next(iter(kind(goldens, "stochastic")))
    assert sidak_level(WIDTH * HEIGHT) == pytest.approx(1 - 0.99 ** (1 / 1728))
    v = s.V.copy()
    v[0, 0] = np.nan
    assert judge(v, s).failing == 1


def test_a_failing_frame_writes_images_for_a_person(goldens, tmp_path, monkeypatch):
    for g in (next(iter(kind(goldens, "deterministic"))), next(iter(kind(goldens, "stochastic")))):
        v = shifted(g.V, 1)
        v[3, 3] = np.nan
        d = write_failure(v, g, judge(v, g), tmp_path)
        names = {"frame.png", "golden.png", "diff.png", "figure.png"} | ({"z.png"} if g.kind == "stochastic" else set())
        assert d == tmp_path / f"{g.scene}-{g.technique}" and names <= {p.name for p in d.iterdir()}
    monkeypatch.setenv("WSOFT_GOLDEN_OUT", str(tmp_path / "elsewhere"))
    assert out_dir() == tmp_path / "elsewhere"
    monkeypatch.delenv("WSOFT_GOLDEN_OUT")
    assert out_dir().name == "wsoft-golden"


def test_write_command_refuses_bad_arguments(capsys):
    assert main([]) == 2
    assert main(["--write", "no_such_technique"]) == 2
    assert "no_such_technique" in capsys.readouterr().err
    assert main(["--write", "--jobs", "many"]) == 2
    assert "--jobs" in capsys.readouterr().err


@pytest.mark.slow
def test_golden_frames_match_by_statistics():
    """Every frame rendered now passes its rule against its golden; a failing one has its images
    written (the message names the folder); a frame of a technique or stage added since has no
    golden yet and is named (``python tests/golden.py --write TECHNIQUE`` adds it)."""
    failures, missing, new, judged = check_all()
    assert judged >= 270
    assert not failures and not missing, (f"{len(failures)} of {judged} golden frames ({WIDTH}x{HEIGHT}) fail: " + "; ".join(failures)
                                          + (f"; no longer rendered: {missing}" if missing else ""))
    assert not new, f"frames without a golden (add them with python tests/golden.py --write TECHNIQUE): {new}"


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))


def test_a_reference_pixel_of_k_of_n_samples_gets_the_exact_binomial_tail():
    """A golden of V 0.999: one blocked sample of 8 (7/8) happens in about 1 frame of 125 per pixel and
    passes, where the Z-test alone put it at |z| 11; every sample blocked (0/8) fails."""
    gold = np.full((HEIGHT, WIDTH), 0.999)
    g = Golden("s", "reference", {"samples": 8}, [], "stochastic", gold, var=gold * (1 - gold), n_test=8, n_gold=1024)
    v = np.ones((HEIGHT, WIDTH))
    v.ravel()[:40] = 7 / 8
    assert judge(v, g).failing == 0
    v.ravel()[:40] = 0.0
    assert judge(v, g).failing == 40
    w = v.copy()
    w.ravel()[:40] = 0.3  # not a whole count of 8: the Z-test judges it
    assert judge(w, g).failing == 40
