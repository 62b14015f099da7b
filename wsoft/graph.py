"""The frame graph: passes with declared inputs and outputs, culled to what is requested.

Resources are named by a small frozen :class:`Key` (kind, light, technique, variant), never by
formatted strings, so several techniques can share one graph: a depth map at 1024² of a light
is one resource whoever asks for it, while each technique's visibility carries its technique.

A render registers every pass a technique *could* use (providers decide the variant a scene
needs: no cutouts -> no alpha-tested pass), then asks for outputs. Only passes that feed those
outputs run, in registration order (which is topological: a provider registers a pass's inputs
before the pass). Each pass has a *kind* (:data:`PASS_KINDS`), so stats can be grouped without
parsing names. Resources are immutable once written: a pass creates new arrays rather than
editing its inputs (``check_immutable`` verifies it). Intermediates are released after their
last consumer unless requested. Time Warp spends compiling or loading a module during a pass (a
cold kernel cache: seconds) is taken out of the pass's time and recorded as its ``compile_ms``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

import numpy as np
import warp as wp

from wsoft.parallel import compile_time

PASS_KINDS = ("scene", "gbuffer", "light_map", "technique", "reference", "shade", "resolve", "metric")


@dataclass(frozen=True, order=True)
class Key:
    """A resource of the frame graph.

    ``kind``: what it is (``gbuffer``, ``light_depth``, ``visibility``, ``essm_sat``...: what a
    technique's :class:`~wsoft.techniques.PassSpec` names); ``flavour``: how a resource of that
    kind was made, when several ways exist (a depth map ``_alpha``-tested, ``_conservative``...);
    ``light``: the light's label, or empty; ``technique``: the technique (instance label) it
    belongs to, or empty for a resource any technique may share; ``variant``: what else tells it
    apart (a map size, the parameters it was built with)."""

    kind: str
    light: str = ""
    technique: str = ""
    variant: str = ""
    flavour: str = ""

    def __str__(self) -> str:
        inner = ":".join(x for x in (self.technique, self.light) if x)
        return self.kind + self.flavour + (f"[{inner}]" if inner else "") + self.variant


class Resources(dict):
    """Resources by :class:`Key`; a key's string (``"ssm_search[Light]"``) finds it too."""

    def __getitem__(self, k):
        if isinstance(k, str):
            for key in self.keys():
                if str(key) == k:
                    return dict.__getitem__(self, key)
            raise KeyError(k)
        return dict.__getitem__(self, k)

    def __contains__(self, k) -> bool:
        if isinstance(k, str):
            return any(str(key) == k for key in self.keys())
        return dict.__contains__(self, k)


@dataclass
class Pass:
    """One step of a frame. ``run(res)`` reads ``res[input]`` and returns ``{output: value}``.

    ``kind``: one of :data:`PASS_KINDS`; ``stage``: a technique's own name for the step (ESSM's
    ``basis``, ``sat``, ``shadow``); ``technique`` / ``light``: whose pass it is (empty when shared)."""

    name: str
    inputs: tuple[Key, ...]
    outputs: tuple[Key, ...]
    run: Callable[[Resources], dict[Key, Any]]
    kind: str = "technique"
    stage: str = ""
    technique: str = ""
    light: str = ""

    def __post_init__(self):
        if self.kind not in PASS_KINDS:
            raise ValueError(f"pass {self.name!r}: kind {self.kind!r} is not one of {', '.join(PASS_KINDS)}")


@dataclass
class FrameGraph:
    passes: dict[str, Pass] = field(default_factory=dict)
    producers: dict[Key, str] = field(default_factory=dict)

    def add(self, p: Pass) -> Pass:
        """Add a pass once: a second add of the same name returns the first (it must declare the
        same inputs and outputs: one name, one computation)."""
        if p.name in self.passes:
            q = self.passes[p.name]
            if (q.inputs, q.outputs) != (p.inputs, p.outputs):
                raise ValueError(f"pass {p.name!r} registered twice with different inputs or outputs")
            return q
        for out in p.outputs:
            if out in self.producers:
                raise ValueError(f"resource {str(out)!r} written by both {self.producers[out]!r} and {p.name!r}")
        for out in p.outputs:
            self.producers[out] = p.name
        self.passes[p.name] = p
        return p

    def find(self, k: Key | str) -> Key:
        """The key itself, or the registered key whose string is ``k``."""
        if isinstance(k, Key):
            return k
        for key in self.producers:
            if str(key) == k:
                return key
        raise KeyError(f"no pass produces {k!r}")

    def closure(self, requested: Iterable[Key | str]) -> set[str]:
        """Names of the passes the requested resources need (transitively)."""
        needed: set[str] = set()
        stack = [self.find(k) for k in requested]
        while stack:
            res = stack.pop()
            name = self.producers.get(res)
            if name is None:
                raise KeyError(f"no pass produces {str(res)!r}")
            if name in needed:
                continue
            needed.add(name)
            stack.extend(self.passes[name].inputs)
        return needed

    def schedule(self, requested: Iterable[Key | str]) -> list[Pass]:
        """Passes needed for ``requested`` resources, in registration (topological) order."""
        needed = self.closure(requested)
        return [p for n, p in self.passes.items() if n in needed]

    def execute(self, requested: Iterable[Key | str], device: str, *, keep: Iterable[Key | str] = (), check_immutable: bool = False,
                progress: Callable[[int, int, str | None], None] | None = None) -> tuple[Resources, list[dict]]:
        """Run the scheduled passes; returns the requested (and ``keep``) resources and one record
        per pass (name, kind, stage, ms, cpu_ms, compile_ms, bytes of what it wrote). ``ms`` and
        ``cpu_ms`` leave out the time Warp spent compiling or loading modules during the pass, which
        is ``compile_ms`` (wall). An intermediate is dropped after its last consumer ran.
        ``check_immutable``: raise if a pass changed a resource it did not write. ``progress``: called
        as ``progress(done, total, name)`` before each pass and as ``progress(total, total, None)``
        after the last."""
        requested = [self.find(k) for k in requested]
        kept = set(requested) | {self.find(k) for k in keep}
        order = self.schedule(requested)
        last_use: dict[Key, int] = {}
        for i, p in enumerate(order):
            for k in p.inputs:
                last_use[k] = i
        res = Resources()
        records = []
        snapshots: dict[Key, list[np.ndarray]] = {}
        for i, p in enumerate(order):
            if progress is not None:
                progress(i, len(order), p.name)
            wp.synchronize_device(device)
            t0, c0 = time.perf_counter(), time.process_time()
            out = p.run(res)
            wp.synchronize_device(device)
            t1, c1 = time.perf_counter(), time.process_time()
            compile_s, compile_cpu_s = compile_time(t0, t1)
            missing = set(p.outputs) - set(out)
            if missing:
                raise RuntimeError(f"pass {p.name!r} did not write {sorted(str(k) for k in missing)}")
            extra = set(out) - set(p.outputs)
            if extra:
                raise RuntimeError(f"pass {p.name!r} wrote undeclared {sorted(str(k) for k in extra)}")
            if check_immutable:
                for k, snap in snapshots.items():
                    if k in res and any(not np.array_equal(a, b) for a, b in zip(snap, _host_arrays(res[k]))):
                        raise RuntimeError(f"pass {p.name!r} modified {str(k)!r}, written by {self.producers[k]!r}")
                for k in p.outputs:
                    snapshots[k] = [a.copy() for a in _host_arrays(out[k])]
            res.update(out)
            records.append({"name": p.name, "kind": p.kind, "stage": p.stage, "technique": p.technique, "light": p.light,
                            "ms": 1e3 * (t1 - t0 - compile_s), "cpu_ms": 1e3 * max(c1 - c0 - compile_cpu_s, 0.0),
                            "compile_ms": 1e3 * compile_s, "bytes": buffer_bytes(out)})
            for k in p.inputs:
                if last_use.get(k) == i and k not in kept and k in res:
                    del res[k]
                    snapshots.pop(k, None)
        if progress is not None:
            progress(len(order), len(order), None)
        return res, records


def _host_arrays(value) -> list[np.ndarray]:
    if hasattr(value, "arrays"):
        return [a.numpy() if isinstance(a, wp.array) else np.asarray(a) for a in value.arrays().values()]
    if isinstance(value, wp.array):
        return [value.numpy()]
    if isinstance(value, np.ndarray):
        return [value]
    if isinstance(value, dict):
        return [np.asarray(v) for v in value.values() if isinstance(v, np.ndarray)]
    return []


def buffer_bytes(resources: dict) -> dict[str, int]:
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
