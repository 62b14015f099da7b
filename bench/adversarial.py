"""Sweep ``adversarial``: the adversarial corpus (:mod:`wsoft.stages.adversarial`) x every technique,
through the command line, into ``reports/adversarial.md``.

Every case runs in-process exactly as a user runs it (``wsoft render STAGE -t TECH --out ...
--stats ...``) and is judged by the corpus; ``tests/test_adversarial.py`` runs the same cases on
CPU in CI. The report adds what each technique does with a light inside a closed mesh.
"""

from __future__ import annotations

import contextlib
import json
import os

import numpy as np

from wsoft.stages.adversarial import CASES, H, KNOWN, MAP, REF_SAMPLES, W, Case, Result, judge, write_stage


# what the corpus sets beyond a technique's quick parameters: the reference's samples, and izb
# without anti-aliasing (the checks judge a pixel by its centre sample: an anti-aliased pixel
# mixes what it covers)
CORPUS_PARAMS = {"reference": {"samples": REF_SAMPLES}, "izb": {"aa": "none"}}


def technique_args(technique: str, map_size: int = MAP) -> list[str]:
    """``--set`` arguments of a technique in the corpus: its quick parameters
    (``Technique.quick_params``), ``map_size`` for its map or grid (``Technique.size_param``) and
    :data:`CORPUS_PARAMS`."""
    from wsoft.techniques import get_technique

    cls = get_technique(technique)
    params = {**cls.quick_params, **({cls.size_param: map_size} if cls.size_param else {}), **CORPUS_PARAMS.get(technique, {})}
    return [a for k, v in params.items() for a in ("--set", f"{k}={v}")]


def run_cli(stage: str, technique: str, out_dir: str, name: str, map_size: int = MAP, args: tuple[str, ...] = (),
            judged_time: float | None = None) -> Result:
    """``wsoft render STAGE -t TECHNIQUE [ARGS]`` in-process, as a user runs it; the EXR read back (of the
    frame at ``judged_time`` when ``ARGS`` render a sequence)."""
    from wsoft.cli import run_captured
    from wsoft.io import read_exr
    from wsoft.pipeline.sequence import frame_path

    exr = os.path.join(out_dir, f"{name}-{technique}.exr")
    stats = os.path.join(out_dir, f"{name}-{technique}.json")
    for p in (exr, stats):
        with contextlib.suppress(FileNotFoundError):
            os.remove(p)
    rc, _, err = run_captured(["render", stage, "-t", technique, "--width", W, "--height", H, "--device", "cpu",
                               *technique_args(technique, map_size), *args, "--out", exr, "--stats", stats])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    res = Result(rc=rc, stderr=err, warnings=[ln[len("warning: "):] for ln in lines if ln.startswith("warning: ")])
    errs = [ln for ln in lines if ln.startswith("wsoft: error: ")]
    res.error = errs[0][len("wsoft: error: "):] if errs else ""
    if rc == 0:
        if judged_time is not None:
            exr, stats = frame_path(exr, judged_time), frame_path(stats, judged_time)
        with open(stats) as f:
            res.stats = json.load(f)
        res.channels = read_exr(exr)
    return res


def supports(stage: str, technique: str) -> bool:
    """Does ``technique`` support the stage's light (``ssm`` has no point lights; ``izb`` no light whose
    receivers need a cube map), as the frame graph decides it? Unloadable stages: yes."""
    import wsoft
    from wsoft.errors import WsoftError
    from wsoft.pipeline.build import build_graph

    try:
        scene = wsoft.load_scene(stage)
        if not scene.lights:
            return True
        built = build_graph(scene, technique, strict=False)
    except WsoftError:
        return True
    return bool(built.lights[built.labels[0]])


class Corpus:
    """The cases' stages written into ``folder`` on demand, and their renders (cached per technique)."""

    def __init__(self, folder: str):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)
        self.stages: dict[str, str] = {}
        self.results: dict[tuple[str, str], Result] = {}
        self.by_name = {c.name: c for c in CASES}

    def stage(self, name: str) -> str:
        """The path of case (or base) ``name``'s stage, written on first use."""
        if name not in self.stages:
            self.stages[name] = write_stage(name, self.folder)
        return self.stages[name]

    def result(self, name: str, technique: str) -> Result:
        """``name``'s stage rendered by ``technique`` through the command line (once)."""
        key = (name, technique)
        if key not in self.results:
            case = self.by_name.get(name)
            self.results[key] = run_cli(self.stage(name), technique, self.folder, name, case.map_size if case else MAP,
                                        case.args if case else (), case.judged_time if case else None)
        return self.results[key]

    def frame(self, name: str, technique: str) -> dict | None:
        """The channels of :meth:`result` (None unless it exited 0)."""
        return self.result(name, technique).channels

    def run(self, case: Case, technique: str) -> tuple[Result | None, list[str]]:
        """(result, problems); (None, []) when the technique does not support the stage's light."""
        if not supports(self.stage(case.name), technique):
            return None, []
        res = self.result(case.name, technique)
        return res, judge(case, technique, res, lambda other: self.frame(other, technique))


def run_all(folder: str, techniques: list[str], cases: list[Case] | None = None):
    """Every case x technique: yields (case, technique, Result, problems); skips unsupported pairs."""
    corpus = Corpus(folder)
    for case in CASES if cases is None else cases:
        for t in techniques:
            res, problems = corpus.run(case, t)
            if res is not None:
                yield case, t, res, problems


# --------------------------------------------------------------------------- the sweep


def cases(quick: bool = False, devices=None) -> list[dict]:
    return [{"corpus": "adversarial", "frame": f"{W}x{H}", "map": MAP, "ref_samples": REF_SAMPLES}]


def run_case(case: dict, ctx: dict) -> dict:
    import tempfile

    from wsoft.techniques import TECHNIQUES

    rows = []
    with tempfile.TemporaryDirectory() as d:
        for c, t, res, problems in run_all(d, sorted(TECHNIQUES)):
            v = res.channels["V"][res.channels["A"] > 0] if res.channels is not None else np.zeros(0)
            here = lambda x: x.replace(d + os.sep, "")  # noqa: E731  (messages name the stage file, not the temporary folder)
            warned = [w for w in res.warnings if any(m in w for m in c.message)] or res.warnings[:1]
            rows.append({"case": c.name, "technique": t, "expect": c.expect, "rc": res.rc, "problems": [here(x) for x in problems],
                         "error": here(res.error), "warnings": [here(w) for w in warned],
                         "mean_V": float(v.mean()) if v.size else None, "silent_hazard": c.silent_hazard, "note": c.note,
                         "known": KNOWN.get((c.name, t), ""),
                         "cube_faces": any("cube_faces" in v for v in ((res.stats or {}).get("counters", {}).get("techniques", {})
                                                                       .get(t, {}).values()))})
    return {"results": rows}


def report(rows: list[dict], md, ctx: dict) -> None:
    results = [r for row in rows for r in row["results"]]
    techs = sorted({r["technique"] for r in results})
    names = list(dict.fromkeys(r["case"] for r in results))
    by = {(r["case"], r["technique"]): r for r in results}
    bad = [r for r in results if r["problems"] and not r.get("known")]
    known = [r for r in results if r["problems"] and r.get("known")]
    lines = [
        "# Adversarial corpus: hard inputs x every technique", "",
        f"Command: `{ctx['command']}` (the same cases run in `tests/test_adversarial.py`).", "",
        f"Each case is a small stage rendered through the CLI (`wsoft render STAGE -t TECH`, {W}x{H}, maps {MAP}², "
        f"reference {REF_SAMPLES} samples). A cell is `ok` when the case behaved as it must (exit code, one-line error naming "
        "the prim, the warning, no NaN, and the known answer where there is one), else what went wrong; `-`: the technique "
        "does not support the stage's light. *mean V* is over covered pixels.", "",
        f"**{len(results) - len(bad) - len(known)} of {len(results)} case x technique runs as expected; {len(known)} known defects "
        f"(listed below); {len(bad)} unexpected.**", "",
        "| case | expect | what | " + " | ".join(techs) + " |", "|---|---|---|" + "---|" * len(techs),
    ]
    for n in names:
        first = next(r for r in results if r["case"] == n)
        cells = []
        for t in techs:
            r = by.get((n, t))
            if r is None:
                cells.append("-")
            elif r["problems"] and r.get("known"):
                cells.append("known defect ‡")
            elif r["problems"]:
                cells.append("**" + "; ".join(r["problems"]).replace("|", "/")[:120] + "**")
            elif r["expect"] == "error":
                cells.append("ok (exit 2)")
            else:
                cells.append(f"ok, V̄ {r['mean_V']:.3f}" if r["mean_V"] is not None else "ok")
        lines.append(f"| {n}{' †' if first['silent_hazard'] else ''} | {first['expect']} | {first['note']} | " + " | ".join(cells) + " |")
    lines += ["", "† an input that, left unchecked, gives a silent wrong answer or a traceback.", "",
              "‡ known defects the corpus finds (expected failures in `tests/test_adversarial.py`):", ""]
    lines += [f"* `{r['case']}` x `{r['technique']}`: {r['known']} (measured here: {'; '.join(r['problems'])})" for r in known] or ["* none"]
    lines += ["",
              "## What each case says (first technique)", ""]
    for n in names:
        r = next(r for r in results if r["case"] == n)
        said = r["error"] or "; ".join(r["warnings"]) or "(nothing)"
        lines.append(f"* `{n}`: {said}")
    lamp = [by.get(("lamp_sphere", t)) for t in techs]
    lines += ["", "## A light inside a closed mesh", "",
              "A rect light inside a closed box emits through one hemisphere, which a single frustum holds: every technique "
              "gives full shadow (`lamp_rect`). A sphere light inside the box shines all around: no single frustum holds the "
              "ground beyond, so the shadow-map techniques draw a cube map (`wsoft.lightspace.cube`: six faces with guard "
              "bands) and every receiver lies in one of its faces (`lamp_sphere`); `izb`, whose grid is one frustum, refuses "
              "the light (`-`). The reference traces rays and is right everywhere.", "",
              "| technique | lamp_rect mean V | lamp_sphere mean V | lamp_sphere views |", "|---|---:|---:|---|"]
    for t, r in zip(techs, lamp):
        rr = by.get(("lamp_rect", t))
        views = "-" if r is None else ("cube map" if r.get("cube_faces") else "rays or its own structures")
        lines.append(f"| {t} | {rr['mean_V'] if rr and rr['mean_V'] is not None else float('nan'):.3f} | "
                     f"{r['mean_V'] if r and r['mean_V'] is not None else float('nan'):.3f} | {views} |")
    md.write_text("\n".join(lines) + "\n")
