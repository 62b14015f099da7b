"""The frame graph: passes with declared inputs and outputs, culled to what is requested.

A render registers every pass a technique *could* use (through :class:`RenderContext`'s
providers, which also decide the variant a scene needs: no cutouts -> no alpha-tested
pass), then asks for outputs. Only passes that feed those outputs run; the stats list
them with their times.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import warp as wp


@dataclass
class Pass:
    """One step of a frame. ``run(res)`` reads ``res[input]`` and returns ``{output: value}``."""

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    run: Callable[[dict[str, Any]], dict[str, Any]]
    kind: str = "core"  # core | technique | resolve

    def describe(self) -> dict:
        return {"name": self.name, "inputs": list(self.inputs), "outputs": list(self.outputs), "kind": self.kind}


@dataclass
class FrameGraph:
    passes: dict[str, Pass] = field(default_factory=dict)
    producers: dict[str, str] = field(default_factory=dict)

    def add(self, p: Pass) -> Pass:
        """Add a pass once (a second add of the same name returns the first)."""
        if p.name in self.passes:
            return self.passes[p.name]
        for out in p.outputs:
            if out in self.producers:
                raise ValueError(f"resource {out!r} written by both {self.producers[out]!r} and {p.name!r}")
            self.producers[out] = p.name
        self.passes[p.name] = p
        return p

    def schedule(self, requested: list[str]) -> list[Pass]:
        """Passes needed for ``requested`` resources, in registration (topological) order."""
        needed: set[str] = set()
        stack = list(requested)
        while stack:
            res = stack.pop()
            name = self.producers.get(res)
            if name is None:
                raise KeyError(f"no pass produces {res!r}")
            if name in needed:
                continue
            needed.add(name)
            stack.extend(self.passes[name].inputs)
        return [p for n, p in self.passes.items() if n in needed]

    def execute(self, requested: list[str], device: str) -> tuple[dict[str, Any], list[dict]]:
        """Run the scheduled passes; returns resources and one record per pass (name, ms, cpu_ms)."""
        res: dict[str, Any] = {}
        records = []
        for p in self.schedule(requested):
            wp.synchronize_device(device)
            t0, c0 = time.perf_counter(), time.process_time()
            out = p.run(res)
            wp.synchronize_device(device)
            t1, c1 = time.perf_counter(), time.process_time()
            missing = set(p.outputs) - set(out)
            if missing:
                raise RuntimeError(f"pass {p.name!r} did not write {sorted(missing)}")
            res.update(out)
            records.append({"name": p.name, "ms": 1e3 * (t1 - t0), "cpu_ms": 1e3 * (c1 - c0), "kind": p.kind})
        return res, records


def buffer_bytes(resources: dict[str, Any]) -> dict[str, int]:
    """Bytes of every device array held by the resources, named ``resource.field``."""
    out: dict[str, int] = {}
    for key, val in resources.items():
        if hasattr(val, "arrays"):
            arrays = val.arrays()
        elif isinstance(val, (wp.array, np.ndarray)):
            arrays = {"data": val}
        else:
            continue
        for name, arr in arrays.items():
            itemsize = arr.dtype.itemsize if isinstance(arr, np.ndarray) else wp.types.type_size_in_bytes(arr.dtype)
            out[f"{key}.{name}"] = int(arr.size * itemsize)
    return out
