"""A triangle soup built from meshes: each mesh read once, the soup concatenated once.

The loader reads a mesh into a :class:`MeshPart` (world or prototype points, triangles into them,
per-triangle material and texture coordinates, per-mesh flags); a :class:`Soup` appends parts one
after another, renumbering each part's triangles into the soup's points, and :meth:`Soup.arrays`
gives the per-triangle arrays a :class:`~wsoft.scene.types.Scene` or a
:class:`~wsoft.scene.types.Prototype` holds.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class MeshPart(NamedTuple):
    """One mesh, triangulated, in the frame it is placed in."""

    points: np.ndarray  # [V, 3] float64
    triangles: np.ndarray  # [T, 3] int32 into points
    material: np.ndarray  # [T] int32 index into the scene's materials
    uv: np.ndarray  # [T, 3, 2] float32 texture coordinates per corner
    double_sided: bool  # UsdGeom's doubleSided
    closed: int  # +1 / -1 closed surface facing out / in, 0 open (wsoft.scene.usd_mesh.closed_orientation)
    dynamic: bool  # a dynamic caster
    baked: np.ndarray | None  # [T, 3, 3] baked light per corner, None when the mesh has none
    faces: np.ndarray  # [T] the USD face each triangle comes from


class Soup:
    """Mesh parts appended in order; :meth:`arrays` concatenates them."""

    def __init__(self):
        self.parts: list[MeshPart] = []
        self.point_ranges: list[tuple[int, int, int]] = []  # per part: (prim, first point, point count)
        self.vertex_count = 0

    def add(self, mesh: MeshPart, prim: int) -> tuple[int, int]:
        """Append ``mesh`` as prim ``prim``'s triangles; returns (its first point, its point count)."""
        first, n = self.vertex_count, len(mesh.points)
        self.parts.append(mesh)
        self.point_ranges.append((prim, first, n))
        self.vertex_count += n
        return first, n

    def arrays(self) -> dict[str, np.ndarray | None]:
        """The soup as a :class:`~wsoft.scene.types.Scene`'s fields: ``points`` [V, 3] float32,
        ``triangles`` [T, 3] int32, and per triangle ``tri_prim``, ``tri_material``, ``tri_uv``,
        ``tri_double_sided``, ``tri_closed``, ``tri_dynamic``, ``tri_face`` and ``tri_baked`` (None
        when no part has baked light)."""
        parts = self.parts
        if not parts:
            return dict(points=np.zeros((0, 3), np.float32), triangles=np.zeros((0, 3), np.int32), tri_prim=np.zeros(0, np.int32),
                        tri_material=np.zeros(0, np.int32), tri_uv=np.zeros((0, 3, 2), np.float32), tri_double_sided=np.zeros(0, bool),
                        tri_closed=np.zeros(0, np.int8), tri_dynamic=np.zeros(0, bool), tri_baked=None, tri_face=np.zeros(0, np.int32))
        counts = [len(m.triangles) for m in parts]

        def per_tri(values, dtype) -> np.ndarray:  # one value per part, repeated over its triangles
            return np.concatenate([np.full(n, v, dtype) for v, n in zip(values, counts)])

        return dict(
            points=np.concatenate([m.points for m in parts]).astype(np.float32),
            triangles=np.concatenate([m.triangles + first for m, (_, first, _) in zip(parts, self.point_ranges)]).astype(np.int32),
            tri_prim=per_tri([prim for prim, _, _ in self.point_ranges], np.int32),
            tri_material=np.concatenate([m.material for m in parts]).astype(np.int32),
            tri_uv=np.concatenate([m.uv for m in parts]).astype(np.float32),
            tri_double_sided=per_tri([m.double_sided for m in parts], bool),
            tri_closed=per_tri([m.closed for m in parts], np.int8),
            tri_dynamic=per_tri([m.dynamic for m in parts], bool),
            tri_baked=baked_corners([(m.baked, n) for m, n in zip(parts, counts)]),
            tri_face=np.concatenate([m.faces.astype(np.int32) for m in parts]),
        )


def baked_corners(parts: list[tuple[np.ndarray | None, int]]) -> np.ndarray | None:
    """Per-corner baked light [T, 3, 3] (NaN where a mesh has none), or None if no mesh has any."""
    if all(b is None for b, _ in parts):
        return None
    return np.concatenate([np.full((n, 3, 3), np.nan, np.float32) if b is None else b.astype(np.float32) for b, n in parts])
