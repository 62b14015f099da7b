"""What a case's frame must show: the checks :class:`~wsoft.stages.adversarial.common.Case` names."""

from __future__ import annotations

import math

import numpy as np

from wsoft.stages.adversarial.surfaces import SUN_WALL_ANGLE, SUN_WALL_HEIGHT, SUN_WALL_TOWARD, SUN_WALL_X

def _covered(ch):
    return ch["A"] > 0


def all_dark(ch, base=None, technique="") -> str | None:
    """Every covered pixel in shadow (filtered techniques may leak a little at the shade's rim)."""
    v = ch["V"][_covered(ch)]
    limit = 0.0 if technique in ("reference", "hard") else 0.03
    return None if v.size and v.mean() <= limit else f"mean V {v.mean():.3f} on covered pixels, want <= {limit}"


def all_lit(ch, base=None, technique="") -> str | None:
    """Nothing between the light and any covered pixel: V = 1 (a flat receiver square to the light
    alone in the map once made essm and vssm shadow themselves on 30% of the pixels)."""
    v = ch["V"][_covered(ch)]
    return None if v.size > 100 and v.min() >= 1.0 - 1e-6 else f"min V {v.min():.3f}, {int((v < 0.999).sum())} pixels below 1"


def _same_v(ch, other, what: str) -> str | None:
    """``other``'s V on the pixels both frames cover (more than 100 of them), to 1e-6."""
    both = _covered(ch) & (other["A"] > 0)
    d = np.abs(ch["V"] - other["V"])[both]
    return None if both.sum() > 100 and d.max() <= 1e-6 else f"V differs from {what} by up to {d.max():.3g} on {both.sum()} pixels"


def same_as_base(ch, base, technique="") -> str | None:
    """The base's V on the pixels both cover (out-of-view geometry must not move a shadow)."""
    return _same_v(ch, base, "the base")


def far_side_dark(ch, base=None, technique="") -> str | None:
    """Pixels whose normal turns away from the whole light (its top at z = 4, 1 x 1) are dark."""
    cov = _covered(ch)
    n = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], -1)
    p = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], -1)
    corners = np.array([[x, y, 4.0] for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    behind = np.all(np.einsum("hwi,khwi->khw", n, corners[:, None, None, :] - p[None]) < 0, axis=0) & cov
    front = np.all(np.einsum("hwi,khwi->khw", n, corners[:, None, None, :] - p[None]) > 0, axis=0) & cov & (ch["P.Z"] > 0.7)
    if behind.sum() < 20 or front.sum() < 5:
        return f"too few pixels to judge ({behind.sum()} behind, {front.sum()} lit top)"
    if ch["V"][behind].max() > 0:
        return f"{int((ch['V'][behind] > 0).sum())} pixels facing away from the light are lit"
    if ch["V"][front].min() < 0.99:
        return f"the lit top is shadowed (min V {ch['V'][front].min():.3f})"
    return None


# techniques whose V is the light's central direction's, filtered by a kernel of fixed width (no penumbra
# sized from the light: salzman's one blur width for every penumbra)
CENTRAL = ("hard", "pcf", "vsm", "esm", "evsm", "msm", "izb", "salzman", "vsmap")


def _sun_cone(n: int = 2048) -> np.ndarray:
    """``n`` unit directions toward the sun of :func:`_sun_wall`, evenly over its cone (a sunflower
    pattern over the disk of the cone's half-angle)."""
    c = np.asarray(SUN_WALL_TOWARD, np.float64)
    c /= np.linalg.norm(c)
    u = np.cross(c, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(c, u)
    k = np.arange(n) + 0.5
    rad = math.tan(math.radians(0.5 * SUN_WALL_ANGLE)) * np.sqrt(k / n)
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    d = c + rad[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sun_wall_penumbra(half_width: float):
    """A check of :func:`_sun_wall`'s stage with a wall of ``half_width``: the mean V over the ground
    within 0.1 of the exact visible fraction of the sun's cone past the wall (of the light's centre
    alone, never blocked, for the fixed-filter techniques of :data:`CENTRAL`). A map that misses the
    wall gives about 0.97 where the exact answer is about 0.8."""

    def check(ch, base=None, technique="") -> str | None:
        cov = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
        if cov.sum() < 100:
            return f"{int(cov.sum())} ground pixels"
        p = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], -1)[cov].astype(np.float64)
        c = np.asarray(SUN_WALL_TOWARD, np.float64)
        dirs = c[None] / np.linalg.norm(c) if technique in CENTRAL else _sun_cone()
        t = (SUN_WALL_X - p[:, None, 0]) / dirs[None, :, 0]  # along each direction to the wall's plane
        hy = p[:, None, 1] + t * dirs[None, :, 1]
        hz = p[:, None, 2] + t * dirs[None, :, 2]
        blocked = (t > 0) & (hz >= 0.0) & (hz <= SUN_WALL_HEIGHT) & (np.abs(hy) <= half_width)
        exact = 1.0 - blocked.mean(axis=1)
        got = ch["V"][cov].astype(np.float64)
        d = abs(got.mean() - exact.mean())
        return None if d <= 0.1 else f"mean V {got.mean():.3f} on {int(cov.sum())} ground pixels, the exact {exact.mean():.3f}"

    check.__doc__ = f"The sun's visible fraction past a wall {2 * half_width:g} wide, mean over the ground within 0.1."
    return check


def same_as(other: str):
    def check(ch, base, technique="", frames=None) -> str | None:
        return _same_v(ch, frames[other], other)

    check.__doc__ = f"The same V as the stage {other!r} on the same pixels."
    check.wants = other
    return check


def close_to(other: str, tol: float):
    """Mean |V - V_other| at most ``tol`` on the pixels both cover (a moved or rescaled copy of a
    stage: the same shadow up to float rounding and the reference's noise)."""

    def check(ch, base, technique="", frames=None) -> str | None:
        o = frames[other]
        both = _covered(ch) & (o["A"] > 0)
        either = int((_covered(ch) | (o["A"] > 0)).sum())
        if either - both.sum() > 0.01 * either:
            return f"covers {int(_covered(ch).sum())} pixels, {other} {int((o['A'] > 0).sum())} ({either - int(both.sum())} differ)"
        d = np.abs(ch["V"] - o["V"])[both]
        return None if both.sum() > 100 and d.mean() <= tol else f"mean |V - V({other})| {d.mean():.3g} on {both.sum()} pixels, want <= {tol:g}"

    check.__doc__ = f"Within {tol:g} of the stage {other!r} (mean over the pixels both cover)."
    check.wants = other
    return check


def ground_dark(ch, base=None, technique="") -> str | None:
    """The ground's top is dark (the light lies in or below its plane)."""
    g = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
    return None if g.sum() > 100 and ch["V"][g].max() == 0.0 else f"max V {ch['V'][g].max() if g.any() else -1:.3f} on {g.sum()} ground pixels"


def sky_over_square(ch, base=None, technique="") -> str | None:
    """A uniform dome over the base's ground and its square occluder (half-side 1 at height 1): on
    the ground, V = 1 - the form factor from the point to the square (the sky it hides); mean
    |V - that| at most 0.05 over the ground's covered pixels."""
    from wsoft.stages.light_cases import form_factor

    g = _covered(ch) & (np.abs(ch["P.Z"]) < 1e-4)
    if g.sum() <= 100:
        return f"{int(g.sum())} ground pixels covered, want > 100"
    xs, ys = ch["P.X"][g], ch["P.Y"][g]
    truth = 1.0 - np.array([form_factor(float(x), float(y), (-1.0, 1.0, -1.0, 1.0)) for x, y in zip(xs, ys)])
    d = float(np.abs(ch["V"][g] - truth).mean())
    return None if d <= 0.05 else f"mean |V - (1 - form factor)| {d:.3f} on {int(g.sum())} ground pixels, want <= 0.05"
