"""IES photometric profiles (ANSI/IESNA LM-63) for ``UsdLux.ShapingAPI``'s ``shaping:ies:file``.

:func:`parse_ies` reads the text of an LM-63 file: the 1986 form (no version line), ``IESNA91``,
``IESNA:LM-63-1995`` and ``IESNA:LM-63-2002`` headers; ``[KEYWORD] value`` lines; ``TILT=NONE`` and
``TILT=INCLUDE`` (its lamp-to-luminaire geometry, angles and factors read and checked;
``TILT=<file>``, tilt data in another file, is refused); type C photometry (types A and B are
refused); vertical angles from 0 (nadir, the light's −Z) up to 180, ascending, starting at 0 or
90 and ending at 90 or 180; horizontal angles as LM-63's type C symmetries give them: a single 0
(the same in every plane), 0–90 (a quadrant, mirrored into the other three), 0–180 (one half,
mirrored about the 0–180 plane) or 0–360 (every plane). Numbers may run over lines and be
separated by blanks or commas. The candela values are scaled by the candela multiplier and the
ballast factor (and the 1995 form's ballast-lamp photometric factor).

A profile is sampled by :meth:`IesProfile.sample` (host) and
:func:`~wsoft.lightspace.light.ies_factor` (device): bilinear in the two angles over its angle
sets, 0 outside its vertical range. Any malformed file is an :class:`IesError` whose message names
what is wrong; the loader turns it into one line naming the file, the prim and the attribute.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

TYPE_C = 1
TYPE_NAMES = {1: "C", 2: "B", 3: "A"}
VERSIONS = {"IESNA:LM-63-2002": "2002", "IESNA:LM-63-1995": "1995", "IESNA91": "1991"}


class IesError(ValueError):
    """A profile that cannot be read: the message says what is wrong (and where in the file)."""


@dataclass(frozen=True)
class IesProfile:
    """A type C photometric profile: candela values ``candela[h][v]`` at the vertical angles
    ``vertical`` (degrees off the nadir, ascending) in the planes at the horizontal angles
    ``horizontal`` (degrees, ascending, one of LM-63's four symmetric sets), with the multipliers
    applied."""

    vertical: tuple[float, ...]
    horizontal: tuple[float, ...]
    candela: tuple[tuple[float, ...], ...]
    version: str = "1986"
    """``1986`` (no version line), ``1991``, ``1995`` or ``2002``."""
    keywords: tuple[tuple[str, str], ...] = ()
    tilt: str = "NONE"
    """``NONE`` or ``INCLUDE`` (its factors are read and checked, not applied: they scale the whole
    profile by one number for a fixed mounting, which either normalisation divides out)."""

    def full_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertical angles [V], horizontal angles [H] from 0 to 360, values [V, H] float64): the
        profile over every plane, its symmetric halves or quadrants mirrored (mirrored angles are
        exact copies of the file's, so bilinear lookups in it equal those in the file's set)."""
        v = np.asarray(self.vertical, np.float64)
        h = np.asarray(self.horizontal, np.float64)
        c = np.asarray(self.candela, np.float64)  # [H, V]
        if len(h) == 1:
            return v, np.array([0.0, 360.0]), np.repeat(c.T, 2, axis=1)
        last = h[-1]
        if last == 90.0:
            full = np.unique(np.concatenate([h, 180.0 - h, 180.0 + h, 360.0 - h]))
        elif last == 180.0:
            full = np.unique(np.concatenate([h, 360.0 - h]))
        else:
            full = h
        cols = [int(np.searchsorted(h, fold_horizontal(a, last))) for a in full]
        return v, full, c[cols].T

    def peak(self) -> float:
        """The largest candela value (> 0: :func:`parse_ies` refuses an all-dark profile)."""
        return float(np.max(self.candela))

    def mean_intensity(self) -> float:
        """The profile's intensity averaged over the whole sphere, ``(1 / 4 pi) * integral I d omega``
        (the trapezoid rule on its angle grid in ``cos`` of the vertical angle, 0 outside its
        vertical range): the light's total flux over 4 pi."""
        v, h, t = self.full_table()
        mu = np.cos(np.radians(v))
        over_h = np.trapezoid(t, np.radians(h), axis=1) if len(h) > 1 else t[:, 0] * 2.0 * math.pi
        return float(abs(np.trapezoid(over_h, mu)) / (4.0 * math.pi))

    def sample(self, vertical_deg: np.ndarray, horizontal_deg: np.ndarray) -> np.ndarray:
        """The candela value at each (vertical, horizontal) pair, bilinear in the two angles over the
        profile's sets (horizontal angles folded by its symmetry), 0 outside its vertical range."""
        v, h, t = self.full_table()
        va = np.asarray(vertical_deg, np.float64)
        ha = np.mod(np.asarray(horizontal_deg, np.float64), 360.0)
        out = np.zeros(np.broadcast(va, ha).shape)
        va, ha = np.broadcast_to(va, out.shape), np.broadcast_to(ha, out.shape)
        inside = (va >= v[0]) & (va <= v[-1])
        if len(v) == 1:
            iv, fv = np.zeros(out.shape, int), np.zeros(out.shape)
        else:
            iv = np.clip(np.searchsorted(v, va, side="right") - 1, 0, len(v) - 2)
            fv = np.clip((va - v[iv]) / (v[iv + 1] - v[iv]), 0.0, 1.0)
        ih = np.clip(np.searchsorted(h, ha, side="right") - 1, 0, len(h) - 2)
        fh = np.clip((ha - h[ih]) / (h[ih + 1] - h[ih]), 0.0, 1.0)
        iv1 = np.minimum(iv + 1, len(v) - 1)
        val = ((1 - fv) * ((1 - fh) * t[iv, ih] + fh * t[iv, ih + 1]) + fv * ((1 - fh) * t[iv1, ih] + fh * t[iv1, ih + 1]))
        out[inside] = val[inside]
        return out


def fold_horizontal(a: float, last: float) -> float:
    """The angle of the profile's own horizontal set that the plane at ``a`` degrees mirrors, for a
    set ending at ``last`` (90: a quadrant; 180: a half; 360: every plane)."""
    a = a % 360.0 if a != 360.0 else 360.0
    if last == 360.0:
        return a
    if a > 180.0:
        a = 360.0 - a
    if last == 90.0 and a > 90.0:
        a = 180.0 - a
    return a


_NUMBER = re.compile(r"[,\s]+")


def _numbers(lines: list[str], count: int, what: str, at: list[int]) -> list[float]:
    """The next ``count`` numbers from ``lines`` starting at line ``at[0]`` (advanced past them)."""
    out: list[float] = []
    while len(out) < count:
        if at[0] >= len(lines):
            raise IesError(f"ends after {len(out)} of the {count} numbers of {what}")
        line = lines[at[0]]
        at[0] += 1
        for tok in _NUMBER.split(line.strip()):
            if not tok:
                continue
            try:
                x = float(tok)
            except ValueError:
                raise IesError(f"line {at[0]}: {tok!r} in {what} is not a number") from None
            if not math.isfinite(x):
                raise IesError(f"line {at[0]}: {tok} in {what} is not finite")
            out.append(x)
    if len(out) > count:  # numbers of the next field on the same line: leave them for it
        rest = " ".join(repr(x) for x in out[count:])
        at[0] -= 1
        lines[at[0]] = rest
    return out[:count]


def parse_ies(text: str) -> IesProfile:
    """The profile in the LM-63 ``text`` (module docstring); :class:`IesError` when it is malformed."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if not any(l.strip() for l in lines):
        raise IesError("is empty")
    first = lines[0].strip().lstrip("\ufeff")
    version = VERSIONS.get(first.upper().replace(" ", ""), None)
    if version is None and first.upper().startswith("IESNA"):
        raise IesError(f"line 1: unknown version {first!r} (read: IESNA:LM-63-2002, IESNA:LM-63-1995, IESNA91, or none for 1986)")
    at = 1 if version else 0
    version = version or "1986"
    keywords = []
    while at < len(lines) and not lines[at].strip().upper().startswith("TILT"):
        s = lines[at].strip()
        m = re.match(r"\[([^\]]+)\]\s*(.*)", s)
        if m:
            keywords.append((m.group(1).strip().upper(), m.group(2).strip()))
        at += 1
    if at >= len(lines):
        raise IesError("has no TILT= line (every LM-63 file has TILT=NONE, TILT=INCLUDE or TILT=<file> before its numbers)")
    tilt = lines[at].strip().split("=", 1)
    value = tilt[1].strip() if len(tilt) == 2 else ""
    if not value:
        raise IesError(f"line {at + 1}: {lines[at].strip()!r} has no value (TILT=NONE or TILT=INCLUDE)")
    at += 1
    pos = [at]
    if value.upper() == "INCLUDE":
        geom, n = _numbers(lines, 2, "the TILT=INCLUDE block's geometry and angle count", pos)
        if geom not in (1.0, 2.0, 3.0):
            raise IesError(f"TILT=INCLUDE: lamp-to-luminaire geometry {geom:g} must be 1, 2 or 3")
        if n < 1 or n != int(n):
            raise IesError(f"TILT=INCLUDE: {n:g} tilt angles (need a whole number >= 1)")
        _numbers(lines, int(n), "the tilt angles", pos)
        factors = _numbers(lines, int(n), "the tilt multiplying factors", pos)
        if min(factors) < 0.0:
            raise IesError("TILT=INCLUDE: a tilt multiplying factor is negative")
        tilt_kind = "INCLUDE"
    elif value.upper() == "NONE":
        tilt_kind = "NONE"
    else:
        raise IesError(f"TILT={value}: tilt data in another file is not read (put it in this file with TILT=INCLUDE, or use TILT=NONE)")
    (lamps, lumens, mult, nv, nh, ptype, units, width, length, height) = _numbers(lines, 10, "the photometric header", pos)
    ballast, bl_factor, watts = _numbers(lines, 3, "the ballast factor, ballast-lamp factor and input watts", pos)
    if ptype != TYPE_C:
        name = TYPE_NAMES.get(int(ptype), f"{ptype:g}") if ptype == int(ptype) else f"{ptype:g}"
        raise IesError(f"photometric type {name}: only type C (1) is read (types A and B measure about other axes)")
    for what, k in (("vertical", nv), ("horizontal", nh)):
        if k < 1 or k != int(k):
            raise IesError(f"{k:g} {what} angles (need a whole number >= 1)")
    if mult <= 0.0:
        raise IesError(f"candela multiplier {mult:g} must be > 0")
    if ballast <= 0.0:
        raise IesError(f"ballast factor {ballast:g} must be > 0")
    v = _numbers(lines, int(nv), "the vertical angles", pos)
    h = _numbers(lines, int(nh), "the horizontal angles", pos)
    cd = _numbers(lines, int(nv) * int(nh), f"the candela values ({int(nh)} x {int(nv)})", pos)
    if any(l.strip() for l in lines[pos[0]:]):
        extra = next(i for i in range(pos[0], len(lines)) if lines[i].strip())
        raise IesError(f"line {extra + 1}: numbers past the {int(nh)} x {int(nv)} candela values (a count in the header is wrong)")
    if any(b <= a for a, b in zip(v, v[1:])) or any(b <= a for a, b in zip(h, h[1:])):
        raise IesError("angles must be strictly ascending (vertical and horizontal)")
    if v[0] not in (0.0, 90.0) or v[-1] not in (90.0, 180.0) or (len(v) == 1 and v[0] != 0.0):
        raise IesError(f"vertical angles {v[0]:g}..{v[-1]:g}: type C sets start at 0 or 90 and end at 90 or 180 degrees")
    if h[0] != 0.0 or (len(h) > 1 and h[-1] not in (90.0, 180.0, 360.0)):
        raise IesError(f"horizontal angles {h[0]:g}..{h[-1]:g}: type C sets are a single 0, 0-90, 0-180 or 0-360 degrees")
    if min(cd) < 0.0:
        raise IesError(f"a candela value is negative ({min(cd):g})")
    scale = mult * ballast * (bl_factor if version in ("1986", "1991", "1995") and bl_factor > 0.0 else 1.0)
    table = tuple(tuple(x * scale for x in cd[j * len(v):(j + 1) * len(v)]) for j in range(len(h)))
    if max(max(r) for r in table) <= 0.0:
        raise IesError("every candela value is 0: the profile emits nothing")
    return IesProfile(vertical=tuple(v), horizontal=tuple(h), candela=table, version=version, keywords=tuple(keywords), tilt=tilt_kind)


def read_ies(path: str) -> IesProfile:
    """The profile in the file ``path`` (:func:`parse_ies`); :class:`IesError` when it cannot be
    read (missing, not text) or is malformed."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise IesError(f"cannot be read ({e.strerror or e})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")  # LM-63 keywords may hold non-ASCII text; the numbers are ASCII
    if "\x00" in text:
        raise IesError("is not a text file (LM-63 profiles are text)")
    return parse_ies(text)


def ies_angle(theta_deg: np.ndarray | float, angle_scale: float) -> np.ndarray:
    """The profile's vertical angle for the angle ``theta_deg`` off the light's −Z under
    ``shaping:ies:angleScale`` as OpenUSD specifies it (the RenderMan formula),
    ``theta_ies = (theta - 180) / (1 + angleScale) + 180``, clamped to [0, 180]: the profile
    stretched by ``1 + angleScale`` about its zenith (180). 0 leaves it as it is; a positive value
    pulls its features toward the nadir (a downlight's beam narrows), a value in (-1, 0) pushes
    them away from it (the beam widens); -1 or less has no meaning (refused by the loader)."""
    t = (np.asarray(theta_deg, np.float64) - 180.0) / (1.0 + angle_scale) + 180.0
    return np.clip(t, 0.0, 180.0)


EXAMPLE = "wsoft_downlight.ies"
"""The bundled example profile (made for the project, no measured luminaire): a quadrant-symmetric
downlight, ``I = 1000 cd cos^4(vertical) (1 + 0.3 cos(2 horizontal))`` over 0-90 degrees in 5-degree
steps (horizontal 0, 22.5 ... 90), LM-63-2002, ``TILT=NONE``."""


def example_path() -> str:
    """The path of the bundled example profile :data:`EXAMPLE` (in a checkout or installed)."""
    from wsoft.usd_scenes import folder

    return str(folder() / "ies" / EXAMPLE)
