"""The sky as a light: a ``UsdLux.DomeLight`` (:class:`Dome`), and the maths every dome pass shares.

How a dome reaches the frame graph
----------------------------------
A DomeLight is read (:func:`wsoft.scene.usd_lights.read_dome`) into an ordinary
:class:`~wsoft.scene.types.Light` of ``kind`` :data:`LIGHT_DOME` (``kind_name`` ``"dome"``) whose
``dome`` field holds a :class:`Dome`. The light's ``color`` and ``intensity`` are the DomeLight's
``inputs:color`` (times the blackbody colour where enabled) and ``inputs:intensity x
2^inputs:exposure``: the radiance arriving from direction ``w`` (a unit vector in the world,
pointing from the receiver toward the sky) is ``color x intensity x texture(w)``
(:func:`radiance`), with ``texture`` 1 where no texture is authored (a constant dome). The
light's ``position`` is the origin, its ``frame`` the dome's rotation (``Dome.rotation``) and its
``shaping`` the default: a dome has no size, no cone and no distance; its ``shadowLink`` and
``inputs:shadow:*`` controls are read as for any light (``shadow_excluded``...).

A technique asks "is this a dome" with :func:`is_dome` (``light.kind == LIGHT_DOME``). Every
technique declines a dome through :meth:`~wsoft.techniques.base.Technique.supports` unless it sets
the class attribute ``dome_refusal = ""`` (the base class carries the one-line reason): a dome
technique sets it, reads ``light.dome`` for its directions and weights, and writes ``V`` = the
visible fraction of the dome's irradiance over the receiver's hemisphere (E_occluded /
E_unoccluded, both cosine weighted about the receiver's normal), the quantity the ray-traced
reference estimates (:mod:`wsoft.reference.dome`). A receiver the dome does not light (E_unoccluded
= 0: a black half-sky under its normal) has V = 1 (nothing to shadow).

Directions and the latlong layout (OpenEXR's, as UsdLux's DomeLight page gives it)
-----------------------------------------------------------------------------
In the dome's own frame +Y is the pole (up). Latitude ``lat`` in [-pi/2, pi/2], longitude ``lon``
in [-pi, pi]: ``w = (cos lat sin lon, sin lat, cos lat cos lon)``, so longitude 0 at latitude 0 is
+Z and longitude pi/2 is +X. Image column 0's left edge is longitude +pi and the right edge of the
last column -pi; row 0's top edge is latitude +pi/2 (the zenith), the bottom row's lower edge
-pi/2. Texel ``(row i, column j)`` of a ``H x W`` image covers ``lon`` in ``pi - 2 pi [j, j+1] / W``
and ``lat`` in ``pi/2 - pi [i, i+1] / H``; it is looked up nearest-texel (:func:`texel_of`). The
world direction is ``rotation @ w`` (``rotation``: the dome prim's world transform, its scale and
translation removed).

Importance sampling (:class:`SamplingTable`)
--------------------------------------------
A texture's texels are drawn with probability proportional to their luminance times
``sin(theta)`` (their solid angle; theta the polar angle from +Y), then uniformly in solid angle
inside the texel: the pdf per steradian of a direction in texel k is ``p_k / area_k``. Draws come
from a 2D CDF: a marginal over rows and a conditional over the columns of each row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LIGHT_DOME = 6
"""The :attr:`~wsoft.scene.types.Light.kind` of a dome light (kernels see the integer)."""

LUMINANCE = (0.2126, 0.7152, 0.0722)  # Rec. 709 weights: a texel's brightness for sampling and "brightest spot"


@dataclass(frozen=True, eq=False)
class SamplingTable:
    """A latlong texture's 2D CDF for drawing directions in proportion to radiance x solid angle.

    ``row_cdf`` shape ``[H + 1]`` float64 from 0 to 1 (the marginal over rows), ``col_cdf`` shape
    ``[H, W + 1]`` float64, each row from 0 to 1 (the conditional over columns), ``prob`` shape
    ``[H, W]`` float64, the probability of each texel (sums to 1), ``area`` shape ``[H]`` float64,
    the solid angle of one texel of each row (steradians)."""

    row_cdf: np.ndarray
    col_cdf: np.ndarray
    prob: np.ndarray
    area: np.ndarray

    def pdf(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Probability per steradian of a direction in texel (``rows``, ``cols``)."""
        return self.prob[rows, cols] / self.area[rows]


@dataclass(frozen=True, eq=False)
class Dome:
    """A DomeLight's directional radiance (relative: the light's ``color x intensity`` multiplies it).

    ``texture``: the latlong ``inputs:texture:file`` as linear radiance, shape ``[H, W, 3]`` float32,
    row 0 the zenith (the layout above); None for a constant dome. ``rotation``: 3x3 float64, world
    <- dome (columns: the dome's X, Y (its pole) and Z in the world). ``asset``: the texture's
    resolved path ("" for none). ``table``: the texture's :class:`SamplingTable` (None: constant)."""

    texture: np.ndarray | None = None
    rotation: np.ndarray = None  # type: ignore[assignment]
    asset: str = ""
    table: SamplingTable | None = None

    def __post_init__(self):
        if self.rotation is None:
            object.__setattr__(self, "rotation", np.eye(3))
        if self.texture is not None and self.table is None:
            object.__setattr__(self, "table", sampling_table(self.texture))

    @property
    def constant(self) -> bool:
        """Is the dome the same in every direction (no texture)?"""
        return self.texture is None

    def description(self) -> str:
        if self.texture is None:
            return "constant"
        h, w = self.texture.shape[:2]
        return f"latlong {w} x {h} ({self.asset.rsplit('/', 1)[-1] or 'in memory'})"


def is_dome(light) -> bool:
    """Is ``light`` a dome (:data:`LIGHT_DOME`; ``light.dome`` then holds its :class:`Dome`)?"""
    return light.kind == LIGHT_DOME


# -- directions and the latlong layout --------------------------------------------------------------
def latlong_direction(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Unit directions in the dome's frame, shape ``[..., 3]``, of latitudes and longitudes (radians)."""
    lat, lon = np.broadcast_arrays(lat, lon)
    c = np.cos(lat)
    return np.stack([c * np.sin(lon), np.sin(lat), c * np.cos(lon)], axis=-1)


def direction_latlong(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(latitude, longitude) of unit directions ``w`` (``[..., 3]``) in the dome's frame."""
    lat = np.arcsin(np.clip(w[..., 1], -1.0, 1.0))
    lon = np.arctan2(w[..., 0], w[..., 2])
    return lat, lon


def texel_of(w: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) of the texel of an ``H x W`` latlong image that directions ``w`` (dome frame) fall in."""
    h, wd = shape
    lat, lon = direction_latlong(w)
    col = np.clip(np.floor((math.pi - lon) / (2.0 * math.pi) * wd).astype(np.int64), 0, wd - 1)
    row = np.clip(np.floor((0.5 * math.pi - lat) / math.pi * h).astype(np.int64), 0, h - 1)
    return row, col


def texel_directions(shape: tuple[int, int]) -> np.ndarray:
    """The centre direction of every texel of an ``H x W`` latlong image (dome frame), ``[H, W, 3]``."""
    h, wd = shape
    lat = 0.5 * math.pi - math.pi * (np.arange(h) + 0.5) / h
    lon = math.pi - 2.0 * math.pi * (np.arange(wd) + 0.5) / wd
    return latlong_direction(lat[:, None], lon[None, :])


def row_solid_angles(h: int, w: int) -> np.ndarray:
    """Solid angle of one texel of each row of an ``H x W`` latlong image, ``[H]`` (steradians)."""
    theta = math.pi * np.arange(h + 1) / h  # polar angle from the pole at each row edge
    return (2.0 * math.pi / w) * (np.cos(theta[:-1]) - np.cos(theta[1:]))


def radiance(light, w_world: np.ndarray) -> np.ndarray:
    """Radiance (RGB, ``[..., 3]`` float64) arriving from world directions ``w_world`` (unit, toward the sky)."""
    scale = np.asarray(light.color, np.float64) * float(light.intensity)
    dome: Dome = light.dome
    if dome.texture is None:
        return np.broadcast_to(scale, w_world.shape[:-1] + (3,)).copy()
    w = np.asarray(w_world, np.float64) @ np.asarray(dome.rotation, np.float64)  # world -> dome (rotation is orthonormal)
    r, c = texel_of(w, dome.texture.shape[:2])
    return dome.texture[r, c].astype(np.float64) * scale


# -- importance sampling ----------------------------------------------------------------------------
def sampling_table(texture: np.ndarray) -> SamplingTable:
    """The :class:`SamplingTable` of a latlong radiance ``texture`` (``[H, W, 3]``): texels drawn in
    proportion to luminance x solid angle. An all-black texture samples uniformly in solid angle."""
    h, w = texture.shape[:2]
    area = row_solid_angles(h, w)
    lum = np.maximum(np.asarray(texture, np.float64) @ np.asarray(LUMINANCE), 0.0)
    weight = lum * area[:, None]
    if not weight.sum() > 0.0:
        weight = np.broadcast_to(area[:, None], (h, w)).copy()
    prob = weight / weight.sum()
    rows = prob.sum(axis=1)
    row_cdf = np.concatenate([[0.0], np.cumsum(rows)])
    row_cdf /= row_cdf[-1]
    col = np.concatenate([np.zeros((h, 1)), np.cumsum(prob, axis=1)], axis=1)
    tot = col[:, -1:].copy()
    tot[tot == 0.0] = 1.0
    col_cdf = col / tot
    return SamplingTable(row_cdf=row_cdf, col_cdf=col_cdf, prob=prob, area=area)


def sample_texels(table: SamplingTable, u1: np.ndarray, u2: np.ndarray, u3: np.ndarray, u4: np.ndarray):
    """Directions drawn from ``table`` by four uniform numbers each (``[N]`` arrays in [0, 1)): the
    texel by ``u1`` (row) and ``u2`` (column), the point inside it uniform in solid angle by ``u3``
    (cos of the polar angle) and ``u4`` (longitude). Returns (dome-frame directions ``[N, 3]``, pdf
    per steradian ``[N]``)."""
    h, w = table.prob.shape
    row = np.clip(np.searchsorted(table.row_cdf, u1, side="right") - 1, 0, h - 1)
    cdf = table.col_cdf[row]
    col = np.clip((cdf <= u2[:, None]).sum(axis=1) - 1, 0, w - 1)
    ct0 = np.cos(math.pi * row / h)
    ct1 = np.cos(math.pi * (row + 1) / h)
    cos_t = ct0 + (ct1 - ct0) * u3  # polar angle from +Y, uniform in solid angle within the row band
    lon = math.pi - 2.0 * math.pi * (col + u4) / w
    lat = np.arcsin(np.clip(cos_t, -1.0, 1.0))
    return latlong_direction(lat, lon), table.pdf(row, col)


# -- unoccluded irradiance (shading) ----------------------------------------------------------------
SH_BANDS = 9  # order-2 spherical harmonics: Ramamoorthi & Hanrahan 2001's irradiance environment map


def irradiance_sh(light, resolution: int = 64) -> np.ndarray:
    """The dome's radiance projected on the 9 real spherical harmonics (world frame), ``[9, 3]``,
    convolved with the clamped cosine (Ramamoorthi & Hanrahan 2001): :func:`irradiance` evaluates
    it. Exact for a constant dome; for a texture accurate to a few percent of E (the order-2 cut
    of a cosine lobe)."""
    dome: Dome = light.dome
    scale = np.asarray(light.color, np.float64) * float(light.intensity)
    if dome.texture is None:
        coeff = np.zeros((SH_BANDS, 3))
        coeff[0] = scale * math.pi / 0.282095  # E = pi L for every normal
        return coeff
    tex = np.asarray(dome.texture, np.float64)
    h, w = tex.shape[:2]
    step = max(1, h // resolution)
    if step > 1:  # box-downsample the texture (radiance averaged over each block's solid angle)
        hh, ww = h // step, w // step
        tex = tex[: hh * step, : ww * step]
        wgt = row_solid_angles(hh * step, ww * step)[: hh * step, None, None]
        tex = (tex * wgt).reshape(hh, step, ww, step, 3).sum(axis=(1, 3)) / (wgt.reshape(hh, step, 1, 1, 1).sum(axis=1) * step)
        h, w = hh, ww
    d = texel_directions((h, w)).reshape(-1, 3) @ np.asarray(dome.rotation, np.float64).T  # world directions
    area = np.repeat(row_solid_angles(h, w), w)
    y = sh_basis(d)  # [N, 9]
    coeff = (y * area[:, None]).T @ (tex.reshape(-1, 3) * scale)  # [9, 3]
    return coeff * _SH_COSINE[:, None]


def sh_basis(d: np.ndarray) -> np.ndarray:
    """The 9 real spherical harmonics at unit directions ``d`` (``[N, 3]``), ``[N, 9]``."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y, 1.092548 * y * z,
                     0.315392 * (3.0 * z * z - 1.0), 1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=1)


# the clamped cosine's convolution factors per band (A0 = pi, A1 = 2 pi / 3, A2 = pi / 4)
_SH_COSINE = np.array([math.pi] + [2.0 * math.pi / 3.0] * 3 + [math.pi / 4.0] * 5)


def irradiance(light, normals: np.ndarray, coeff: np.ndarray | None = None) -> np.ndarray:
    """Unoccluded irradiance (RGB, ``[N, 3]``) from the dome onto surfaces of unit world ``normals``
    (``[N, 3]``): ``coeff`` from :func:`irradiance_sh` (computed when None), clamped at 0."""
    if coeff is None:
        coeff = irradiance_sh(light)
    return np.maximum(sh_basis(np.asarray(normals, np.float64)) @ coeff, 0.0)
