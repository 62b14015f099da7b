"""Sweep ``worlds`` (:mod:`wsoft.bench.worlds`): its cases per preset, the preset variable's error,
the memory and split-band measures on made-up frames, the report's targets and its list of the
techniques not registered, and (slow) the quick sweep on the tiny open_world writing rows and a report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wsoft.bench import worlds, worlds_report
from wsoft.bench.harness import SWEEPS
from wsoft.errors import ParameterError


def test_registered_and_cases_follow_the_preset(monkeypatch):
    assert SWEEPS["worlds"] == "wsoft.bench.worlds"
    monkeypatch.delenv(worlds.PRESET_ENV, raising=False)
    full = worlds.cases(False, ["cpu"])
    assert [c["scene"] for c in full] == ["city", "open_world", "open_world_flyby", "open_world_sunset"]
    assert all((c["width"], c["height"], c["ground_truth"]) == (640, 480, 256) for c in full)
    assert [c["frames"] for c in full if c["kind"] == "sequence"] == ["1:48", "1:48"]
    monkeypatch.setenv(worlds.PRESET_ENV, "cpu")
    cpu = worlds.cases(False, ["cpu"])
    assert all(c["preset"] == "cpu" and c["width"] == 160 for c in cpu)
    quick = worlds.cases(True, ["cpu"])
    assert [c["scene"].split("/")[-1] for c in quick] == ["open_world.usdc", "open_world_flyby.usda", "open_world_sunset.usda"]
    assert all(worlds.TINY in c["scene"] for c in quick)
    monkeypatch.setenv(worlds.PRESET_ENV, "huge")
    with pytest.raises(ParameterError, match=r"\$WSOFT_WORLDS='huge' is not one of full, cpu"):
        worlds.cases(False, ["cpu"])


def test_memory_reads_counters_and_parameters():
    assert worlds.memory("csm", {}, {"map_bytes": 4 << 20}) == {"cascade_bytes": 4 << 20}
    m = worlds.memory("vsmap", {}, {"pool_pages": 2048, "page_size": 128, "pool_mib": 2.5})
    assert m == {"pool_bytes": 2048 * 128 * 128 * 4, "resident_bytes": int(2.5 * 2 ** 20)}
    assert worlds.memory("pcss", {"shadow_map_size": 1024}, {}) == {"map_bytes": 1024 * 1024 * 4}
    assert worlds.memory("reference", {"samples": 16}, {}) == {}


class _Frame:
    """A frame as split_band_error reads it: V, A, P.X/Y/Z and a camera at the origin looking down +x."""

    def __init__(self, V, depth):
        h, w = depth.shape
        m = np.eye(4)
        m[:3, :3] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]  # the camera's -Z (its view) is world +x
        self.stats = {"camera_model": {"to_world": m.tolist()}}
        self.V = V
        self.ch = {"P.X": depth, "P.Y": np.zeros_like(depth), "P.Z": np.zeros_like(depth), "A": np.ones_like(depth)}

    def __getitem__(self, k):
        return self.ch[k]


def test_split_band_error_finds_the_band_around_a_split():
    """Depth grows down the image; the split at depth 50 falls between rows 49 and 50. An error only
    within 4 rows of it gives a large band ratio, an error everywhere a ratio of 1."""
    depth = np.repeat(np.arange(100, dtype=np.float64)[:, None], 60, axis=1) + 0.5
    ref = np.zeros_like(depth)
    V = ref.copy()
    V[46:54] = 0.5
    r = worlds.split_band_error(_Frame(V, depth), ref, [0.1, 50.0, 1000.0], band=16)
    assert r["band_pixels"] == 16 * 60 and r["away_pixels"] == 84 * 60
    assert r["band_mae"] == pytest.approx(0.25) and r["away_mae"] == 0.0 and r["ratio"] is None
    r = worlds.split_band_error(_Frame(np.full_like(ref, 0.2), depth), ref, [0.1, 50.0, 1000.0], band=16)
    assert r["ratio"] == pytest.approx(1.0)
    r = worlds.split_band_error(_Frame(V, depth), ref, [0.1, 1000.0], band=16)  # one cascade: no split in view
    assert r["band_pixels"] == 0 and r["ratio"] is None


def _frame_row(scene, techs):
    ent = [{"technique": "reference", "label": "reference", "params": {"samples": 16, "seed": 1}, "frame_ms": 200.0,
            "error": {"mae_penumbra": 0.04, "mae": 0.01}, "counters": {}, "memory": {}, "warnings": []}]
    if "csm" in techs:
        ent.append({"technique": "csm", "label": "csm", "params": {}, "frame_ms": 50.0, "error": {"mae_penumbra": 0.045, "mae": 0.01},
                    "counters": {"splits": [0.1, 10.0, 100.0], "texel_size": [0.01, 0.1], "partition": "sdsm", "stable": True},
                    "memory": {"cascade_bytes": 8 << 20}, "warnings": [],
                    "split_band": {"band_pixels": 900, "away_pixels": 9000, "band_mae": 0.02, "away_mae": 0.01, "ratio": 2.0}})
    if "pcss" in techs:
        ent.append({"technique": "pcss", "label": "pcss(shadow_map_size=2048)", "params": {"shadow_map_size": 2048}, "frame_ms": 40.0,
                    "error": {"mae_penumbra": 0.08, "mae": 0.02}, "counters": {}, "memory": {"map_bytes": 16 << 20}, "warnings": [],
                    "split_band": {"band_pixels": 900, "away_pixels": 9000, "band_mae": 0.03, "away_mae": 0.02, "ratio": 1.5}})
    if "vsmap" in techs:
        ent.append({"technique": "vsmap", "label": "vsmap", "params": {}, "frame_ms": 80.0, "error": {"mae_penumbra": 0.2, "mae": 0.02},
                    "counters": {"requested": 300, "rendered": 300, "reused": 0, "dense_pages": 12 * 16384, "levels": 12},
                    "memory": {"pool_bytes": 128 << 20, "resident_bytes": 19 << 20}, "warnings": []})
    return {"scene": scene, "light": "/World/Lights/Sun", "device": "cpu", "width": 160, "height": 120, "ground_truth_samples": 64,
            "ground_truth_ms": 9000.0, "entries": ent, "triangles": 100, "preset": "cpu", "machine": {"cpu": "x86_64"}}


def test_report_states_the_targets_and_the_missing_techniques(tmp_path, monkeypatch):
    """With smrt and vsmap unregistered the report names them and still reports csm's rows: csm
    reaches 0.05 faster than the reference (yes), its band ratio 2.0 misses 1.5 (no), and pcss on the
    same band and away pixels (no splits) is its control."""
    import wsoft.techniques as T

    for name in ("smrt", "vsmap"):
        if name in T.TECHNIQUES:
            monkeypatch.delitem(T.TECHNIQUES, name)
    assert worlds.registered()[1] == ["vsmap", "smrt"]
    md = tmp_path / "worlds.md"
    rows = [_frame_row("open_world", ("csm", "pcss", "vsmap"))]
    worlds_report.report(rows, md, {"quick": False, "command": "wsoft bench worlds", "stem": "worlds", "out_dir": tmp_path})
    text = md.read_text()
    assert "Not registered in this process, so not measured: `vsmap`, `smrt`" in text
    assert "`WSOFT_WORLDS=cpu wsoft bench worlds`" in text
    assert "| csm: 50 ms at 0.0450; reference 16 spp 200 ms at 0.0400 | yes |" in text
    assert "= 2.00 | no |" in text
    assert "| (control) the same band and away pixels in pcss(shadow_map_size=2048), one map without splits | open_world | " \
           "band MAE 0.0300 / away 0.0200 = 1.50: csm's ratio is 1.33x the control's | - |" in text
    assert "Warp's scalar CPU backend" in text
    assert (tmp_path / "images" / "worlds" / "open_world-Sun-mae.png").is_file()


def test_dense_share_and_reuse_rows():
    row = _frame_row("open_world", ("vsmap",))
    assert worlds_report.dense_share(row["entries"][1]["counters"]) == pytest.approx(300 / 16384)
    seq = {"scene": "open_world_flyby", "light": "/World/Lights/Sun", "frames": [1.0, 2.0, 3.0], "entries": [
        {"technique": "vsmap", "label": "vsmap", "params": {}, "frame_ms_frames": [90.0, 30.0, 32.0], "temporal": {"flicker": 0.01},
         "counters_frames": [{"requested": 300, "rendered": 300, "reused": 0, "dense_pages": 12 * 16384, "levels": 12},
                             {"requested": 300, "rendered": 20, "reused": 280, "dense_pages": 12 * 16384, "levels": 12},
                             {"requested": 300, "rendered": 40, "reused": 260, "dense_pages": 12 * 16384, "levels": 12}]}]}
    text = "\n".join(worlds_report.target_rows([], [seq], ["vsmap"]))
    assert "smallest 86.7%, mean 90.0% over frames 2..3 | no |" in text
    assert "largest 1.83% (frame 1) | yes |" in text


@pytest.mark.slow
def test_quick_sweep_writes_rows_and_a_report(tmp_path, monkeypatch):
    """``wsoft bench worlds --quick``: the tiny open_world, its flight and its sunset, every row
    written with the registered techniques' entries; the report has the targets."""
    from wsoft.bench.harness import run_sweep

    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path / "cache"))
    assert run_sweep("worlds", quick=True, device=["cpu"], out_dir=str(tmp_path)) == 0
    rows = [json.loads(line) for line in (tmp_path / "worlds-quick.jsonl").read_text().splitlines()]
    assert [r["scene"] for r in rows] == ["open_world", "open_world_flyby", "open_world_sunset"]
    have = worlds.registered()[0]
    for r in rows:
        techs = {e["technique"] for e in r["entries"]}
        assert set(have) <= techs and "reference" in techs
    assert all(np.isfinite(e["error"]["mae_penumbra"]) for e in rows[0]["entries"])
    text = (tmp_path / "worlds-quick.md").read_text()
    assert "## Targets" in text and "## open_world_flyby / Sun (3 frames" in text
