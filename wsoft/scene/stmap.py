"""Where a cutout texture's st comes from on a mesh (:class:`StMap`), as :mod:`wsoft.scene.usd_texture` reads it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StMap:
    """Where a cutout texture's st comes from on a mesh: the primvar ``primvar`` (a
    ``UsdPrimvarReader_float2``'s ``varname``; ``fallback`` on a mesh without it; None: ``fallback``
    everywhere, an unconnected ``st``) mapped by the affine ``matrix`` (the ``UsdTransform2d`` nodes
    between reader and texture, composed: st = ``matrix[:, :2] @ uv + matrix[:, 2]``, 2 x 3 rows).
    Applied on the host per triangle corner at load (:meth:`wsoft.scene.usd_mesh.MeshReader.texture_coords`),
    which is exact: the device interpolates st linearly over a triangle."""

    primvar: str | None
    fallback: tuple[float, float] = (0.0, 0.0)
    matrix: tuple[tuple[float, float, float], tuple[float, float, float]] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    reader: str = ""  # the reader node's path (messages name it)

    @property
    def identity(self) -> bool:
        return self.matrix == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
