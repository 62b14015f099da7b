"""Sweeps on Dask distributed (wsoft.bench.dist): a real LocalCluster and a real ``dask scheduler`` with two
``dask worker`` processes on 127.0.0.1 give the in-process run's rows (error figures equal; times are not
compared); a killed worker and a killed driver lose no row and write none twice; a job that raises or
kills its workers is recorded as failed with its error; without Dask the options are a one-line error.
The sweep is tests/dist_sweep.py (three 48x36 rows on two stages, plus the rows a test asks for)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT, wsoft_cli

import dist_sweep
from wsoft.bench import harness

HERE = Path(__file__).resolve().parent


@pytest.fixture
def dask_installed():
    pytest.importorskip("distributed", reason="Dask is not installed (pip install 'wsoft[dist]'; the test extra installs it)")


@pytest.fixture
def sweep(monkeypatch, tmp_path):
    """The test sweep registered as ``dist-test``, references cached in tmp; ``extra`` sets its added rows."""
    monkeypatch.setitem(harness.SWEEPS, dist_sweep.SWEEP, dist_sweep.MODULE)
    monkeypatch.setenv("WSOFT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("WSOFT_DIST_SWEEP", raising=False)

    def extra(rows: list[dict]) -> None:
        monkeypatch.setenv("WSOFT_DIST_SWEEP", json.dumps(rows))

    return extra


@pytest.fixture(scope="module")
def in_process(tmp_path_factory) -> dict[str, dict]:
    """The sweep's rows run in this process, by key."""
    out = tmp_path_factory.mktemp("in_process")
    mp = pytest.MonkeyPatch()
    mp.setitem(harness.SWEEPS, dist_sweep.SWEEP, dist_sweep.MODULE)
    mp.setenv("WSOFT_CACHE_DIR", str(out / "cache"))
    mp.delenv("WSOFT_DIST_SWEEP", raising=False)
    try:
        assert harness.run_sweep(dist_sweep.SWEEP, quick=True, device=["cpu"], out_dir=str(out)) == 0
    finally:
        mp.undo()
    rows = harness.read_rows(out / f"{dist_sweep.SWEEP}-quick.jsonl")
    assert len(rows) == 3
    return {r["key"]: r for r in rows}


def same_errors(rows: list[dict], in_process: dict[str, dict]) -> None:
    """Every render row has the in-process row's error figures, exactly."""
    renders = [r for r in rows if r["case"]["kind"] == "render"]
    assert sorted(r["key"] for r in renders) == sorted(in_process)
    for r in renders:
        assert r["error"] == in_process[r["key"]]["error"], r["key"]
        assert r["params"] == in_process[r["key"]]["params"]


def test_missing_dask_is_one_line_error(monkeypatch, tmp_path):
    for name in ("dask", "distributed"):
        monkeypatch.setitem(sys.modules, name, None)  # import dask / distributed raise ImportError
    for option in (["--workers", "2"], ["--scheduler", "tcp://127.0.0.1:1"]):
        p = wsoft_cli("bench", "foundation", "--quick", "--out-dir", tmp_path / "r", *option)
        assert p.returncode == 2, p.stderr
        assert p.stderr.strip().count("\n") == 0 and "pip install 'wsoft[dist]'" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "r" / "foundation-quick.jsonl").exists()


def test_bad_distributed_options_are_one_line_errors(dask_installed, tmp_path):
    for option, says in ((["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not both"),
                         (["--workers", "0"], "--workers 0: at least 1"),
                         (["--workers", "1", "--resources", "MACHINE"], "is not NAME=NUMBER"),
                         (["--scheduler", "tcp://127.0.0.1:1", "--resources", "MACHINE=1"], "dask worker --resources MACHINE=1")):
        p = wsoft_cli("bench", "foundation", "--quick", "--out-dir", tmp_path / "r", *option)
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and says in p.stderr, (option, p.stderr)


@pytest.mark.slow
def test_local_cluster_rows_match_in_process_and_failures_are_rows(dask_installed, sweep, in_process, tmp_path, capsys):
    """--workers 2: the render rows equal the in-process run's; the first worker alone (MACHINE=1) times;
    the references land in --cache-dir; a row that raises and a row that kills its worker twice are
    recorded failed, with their errors."""
    sweep([{"kind": "raise"}, {"kind": "crash"}])
    out = tmp_path / "reports"
    shared = tmp_path / "shared"
    assert harness.run_sweep(dist_sweep.SWEEP, quick=True, device=["cpu"], out_dir=str(out), workers=2, cache_dir=str(shared)) == 1
    assert len(list((shared / "references").glob("*.npz"))) == 2  # box_plane's and contact's, in --cache-dir
    err = capsys.readouterr().err
    assert "Dask dashboard: http://127.0.0.1:" in err and "2 Dask workers on 127.0.0.1; 5 jobs" in err
    rows = harness.read_rows(out / f"{dist_sweep.SWEEP}-quick.jsonl")
    assert len(rows) == 5 and len({r["key"] for r in rows}) == 5
    same_errors([r for r in rows if not r.get("failed")], in_process)
    failed = {r["case"]["kind"]: r for r in rows if r.get("failed")}
    assert set(failed) == {"raise", "crash"}
    assert failed["raise"]["error"] == "this row raises on purpose"
    assert failed["crash"]["error"].startswith("KilledWorker")
    timed = [r for r in rows if not r.get("failed")]
    assert {r["worker"]["resources"].get("MACHINE") for r in timed} == {1}  # only the worker that holds MACHINE times
    assert all(r["machine"]["host"] and r["machine"]["load"] is not None and r["worker"]["device"] == "cpu" for r in timed)
    firsts = [r for r in timed if not r["worker"]["scene_was_loaded"]]  # one warm-up per (worker, scene) at most
    assert len({(r["worker"]["pid"], r["scene"]) for r in firsts}) == len(firsts)
    md = (out / f"{dist_sweep.SWEEP}-quick.md").read_text()
    workers = len({r["worker"]["pid"] for r in timed})  # the timing worker, and its successor where the crash row ran first
    assert "--workers 2" in md and "Host `" in md and f"Dask workers: {workers} processes ran the rows" in md
    # a rerun (here in-process) runs the failed row again, never a finished one
    sweep([{"kind": "raise"}])
    assert harness.run_sweep(dist_sweep.SWEEP, quick=True, device=["cpu"], out_dir=str(out)) == 1
    assert "3 already in" in capsys.readouterr().err and len(harness.read_rows(out / f"{dist_sweep.SWEEP}-quick.jsonl")) == 5


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args: list[str], env: dict, log: Path) -> subprocess.Popen:
    return subprocess.Popen(args, env=env, stdout=open(log, "w"), stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)


def stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGKILL)  # the process started here and the children it started (a nanny's worker)
    p.wait(timeout=30)


@pytest.fixture
def cluster(dask_installed, tmp_path):
    """A real ``dask scheduler`` and two ``dask worker`` processes (MACHINE=1 each) on 127.0.0.1, random free ports."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, str(HERE), os.environ.get("PYTHONPATH", "")]),
               WSOFT_CACHE_DIR=str(tmp_path / "worker-cache"))  # the driver's is another folder
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    procs = [start(dask + ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], env, tmp_path / "scheduler.log")]
    try:
        for i in range(2):
            procs.append(start([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1", "--nthreads", "1",
                                "--resources", "MACHINE=1", "--host", "127.0.0.1", "--no-dashboard", "--name", f"w{i}"],
                               env, tmp_path / f"worker{i}.log"))
        yield address, env
    finally:
        for p in reversed(procs):
            stop(p)


def wait_for(test, what: str, timeout: float = 60.0):
    t0 = time.time()
    while time.time() - t0 < timeout:
        got = test()
        if got:
            return got
        time.sleep(0.1)
    raise AssertionError(f"waited {timeout:.0f} s for {what}")


@pytest.mark.slow
def test_real_cluster_survives_a_killed_worker_and_a_killed_driver(cluster, in_process, tmp_path):
    """Through ``dask scheduler`` + 2 ``dask worker``: kill the worker running the slow row (by its pid),
    then the driver; a second driver finishes the sweep: every row once, errors equal to in-process.
    The references come back to the driver's cache (the workers have caches of their own)."""
    address, env = cluster
    marks = tmp_path / "marks"
    marks.mkdir()
    env = dict(env, WSOFT_DIST_SWEEP=json.dumps([{"kind": "slow", "dir": str(marks), "seconds": 2.5}]),
               WSOFT_CACHE_DIR=str(tmp_path / "driver-cache"))
    out = tmp_path / "reports"
    jsonl = out / f"{dist_sweep.SWEEP}-quick.jsonl"
    cmd = [sys.executable, str(HERE / "dist_sweep.py"), "bench", dist_sweep.SWEEP, "--quick", "--device", "cpu", "--out-dir", str(out),
           "--scheduler", address]
    driver = start(cmd, env, tmp_path / "driver1.log")
    try:
        first = wait_for(lambda: sorted(marks.iterdir()), "the slow row to start")[0]
        os.kill(int(first.name.split("-")[1]), signal.SIGKILL)  # its worker process (its nanny starts another)
        wait_for(lambda: len(list(marks.iterdir())) >= 2, "the slow row to run again elsewhere")
        stop(driver)  # the driver, while the slow row runs again
    finally:
        stop(driver)
    before = harness.read_rows(jsonl)
    assert not any(r["case"]["kind"] == "slow" for r in before), "the driver was to be killed before the slow row finished"
    assert len(list((tmp_path / "driver-cache" / "references").glob("*.npz"))) == 2  # box_plane's and contact's, returned
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert f"4 rows, {len(before)} already in" in p.stderr
    rows = harness.read_rows(jsonl)
    assert len(rows) == 4 and len({r["key"] for r in rows}) == 4 and rows[: len(before)] == before
    assert not any(r.get("failed") for r in rows)
    same_errors(rows, in_process)
    assert len(list(marks.iterdir())) >= 3  # killed once, cut off with the driver once, finished


def test_distributed_report_counts_equal_errors_and_groups_by_host(tmp_path):
    """``wsoft bench distributed``'s report: error figures compared setting by setting (one differs
    here), wall-time ratios within a round, frame times per host (never a ratio across hosts)."""
    from wsoft.bench import distributed

    def run(mode, rnd, wall, host, mae, ms, pid=None):
        return {"mode": mode, "round": rnd, "sweep": "pareto", "device": "cpu", "rc": 0, "wall_s": wall, "rows": [
            {"key": "k", "scene": "box_plane", "light": "/World/Light", "host": host, "load": 1.0, "threads": 2, "pid": pid,
             "scene_load_s": 0.5 if pid else None, "scene_was_loaded": False, "compile_s": 0.25 if pid else None, "row_seconds": 3.0,
             "entries": [{"label": "hard", "error": {"mae": mae}, "frame_ms": ms}, {"label": "pcss", "error": {"mae": 0.2}, "frame_ms": 2 * ms}]}]}

    rows = [run("in-process", 0, 10.0, "a", 0.1, 4.0), run("workers=2", 0, 15.0, "a", 0.1, 5.0, pid=7),
            run("workers=2", 1, 30.0, "b", 0.3, 8.0, pid=9), run("in-process", 1, 12.0, "a", 0.1, 4.0)]
    md = tmp_path / "distributed.md"
    distributed.report(rows, md, {"quick": False, "command": "wsoft bench distributed"})
    text = md.read_text()
    assert "per round: 1.50, 2.50." in text and "ratio, 1.20," in text
    assert "round 0 workers=2: 2 of 2 settings" in text and "round 1 workers=2: 1 of 2 settings" in text
    assert "| 0 | workers=2 | a | 1 | 1.0-1.0 | 7.50 | 1.25 |" in text
    assert "| 1 | workers=2 | b | 1 | 1.0-1.0 | 12.00 | - |" in text  # host b has no in-process run: no ratio
    assert "| 0 | a | 7 | box_plane | 0.50 | 0.25 | 3.0 |" in text
