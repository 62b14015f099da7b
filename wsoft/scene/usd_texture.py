"""The UsdPreviewSurface network that feeds a cutout's ``opacity``, evaluated on the host at load.

:class:`OpacityNetwork` follows a ``UsdPreviewSurface``'s ``opacity`` input through the nodes of the
UsdPreviewSurface spec (https://openusd.org/release/spec_usdpreviewsurface.html), through material
and NodeGraph interface inputs (``UsdShade.Input.GetValueProducingAttributes``), and puts each
part of it where it is exact:

* ``UsdUVTexture``: the file is decoded once (PNG and what else Pillow reads; OpenEXR ``.exr``)
  into the one channel the opacity reads, with the spec's channel rules (a grey image's r = g = b; a
  = 1 without alpha). ``sourceColorSpace`` (``sRGB``, or ``auto`` on an 8-bit image of 3 or 4
  channels) decodes r, g and b through the sRGB curve, never a. ``scale`` and ``bias`` of that
  channel (``value * scale + bias``) go into the stored texels: :attr:`Texture.data
  <wsoft.scene.types.Texture.data>` is the node's output. ``wrapS`` / ``wrapT`` are applied on the
  device (:func:`wsoft.scene.surfaces.wrap_coord`); ``black`` is transparent black, scaled and
  biased (:attr:`Texture.border <wsoft.scene.types.Texture.border>`, the bias); ``useMetadata`` takes
  the image's own ``wrapS`` / ``wrapT`` fields (or OpenEXR's ``wrapmodes``) and is ``black``
  without them, as the spec says. ``fallback`` is the opacity where the file cannot be read
  (missing, undecodable, over :data:`MAX_TEXTURE_PIXELS`, a missing UDIM tile), as it is (not
  scaled or biased).
* ``st``: a ``UsdPrimvarReader_float2`` (``varname``: the mesh primvar; its ``fallback`` on a mesh
  without it) through any chain of ``UsdTransform2d`` (``in * scale``, rotated counter-clockwise by
  ``rotation`` degrees, plus ``translation``), composed into one affine
  :class:`~wsoft.scene.types.StMap` per material. The mesh reader applies it to each triangle
  corner's coordinates (:meth:`wsoft.scene.usd_mesh.MeshReader.texture_coords`), which is exact:
  the map is affine and the device interpolates st linearly. An unconnected ``st`` is its value,
  the same st everywhere (a warning).
* UDIM files (``tex.<UDIM>.png``): the tiles are found with ``UsdShade.UdimUtils`` and read as one
  texture each (tile 1001 + u + 10 v for st in [u, u + 1) x [v, v + 1), u and v in 0..9). The mesh
  reader gives each triangle the material of the tile its st centroid lies in (one
  :class:`~wsoft.scene.types.Material` per tile, of the same path) with its st shifted into that
  tile. A tile is clamped at its edges (wrapS / wrapT do not apply): tiles meet edge to edge, and
  repeating or blackening a tile's border would draw seams. One texture per tile rather than an
  atlas keeps the device's sampler and filtering as they are (an atlas would need padding so that
  bilinear filtering never reads a neighbouring tile, and tiles of different sizes); the price is
  that a triangle spanning tiles reads only its centroid's tile, clamped at its edge (a warning
  counts them). Triangles whose st lies in no tile take the fallback (a warning).

A node it cannot evaluate (another shader, a ``UsdPrimvarReader`` of another type, a connection
to a missing prim, a cycle) is one warning naming the node, and the surface is opaque. Non-finite
values on the network's inputs are errors naming the node and the input.
"""

from __future__ import annotations

import io
import math
import os
import re
import tempfile
import warnings
from dataclasses import dataclass

import numpy as np

from wsoft.scene.types import WRAP_BLACK, WRAP_NAMES, Material, StMap, Texture
from wsoft.scene.usd_context import StageContext, pxr

MAX_TEXTURE_PIXELS = 8192 * 8192  # larger textures (67.1 Mpx) are not decoded: a warning, and the texture's fallback
CHANNELS = ("r", "g", "b", "a")
_MAX_CHAIN = 16  # UsdTransform2d nodes followed from a texture's st (more: a cycle)


class TextureError(Exception):
    """A texture that cannot be used; the message says why (one line)."""


@dataclass
class Decoded:
    """One channel of a decoded image: ``values`` [h, w] float32, rows top-down as stored;
    ``srgb_auto``: the spec's ``auto`` rule marks the image sRGB (8 bits, 3 or 4 channels);
    ``wraps``: its own wrapS / wrapT metadata (None where it has none)."""

    values: np.ndarray
    srgb_auto: bool
    wraps: tuple[str | None, str | None]


def decode(data: bytes, channel: str, path: str | None = None) -> Decoded:
    """Channel ``channel`` (r, g, b, a) of the image ``data`` (OpenEXR by its magic number, else
    whatever Pillow reads; ``path``: the file on disk, when it is one). Over
    :data:`MAX_TEXTURE_PIXELS`, or unreadable: a :class:`TextureError`."""
    if data[:4] == b"\x76\x2f\x31\x01":
        return _decode_exr(data, channel, path)
    return _decode_pillow(data, channel)


def _pixels(n: int) -> str:
    return f"{n / 1e6:.1f} Mpx" if n >= 100_000 else f"{n} pixels"


def _over_limit(size: str) -> TextureError:
    return TextureError(f"is {size}, over wsoft's limit of {_pixels(MAX_TEXTURE_PIXELS)} (wsoft.scene.usd_texture.MAX_TEXTURE_PIXELS); "
                        "not decoded")


def _too_large(w: int, h: int) -> TextureError:
    return _over_limit(f"{w} x {h} ({_pixels(w * h)})")


def _decode_pillow(data: bytes, channel: str) -> Decoded:
    from PIL import Image

    with warnings.catch_warnings():  # the size is checked here, against MAX_TEXTURE_PIXELS
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            im = Image.open(io.BytesIO(data))
        except Image.DecompressionBombError as exc:
            m = re.search(r"\((\d+) pixels\)", str(exc))  # over twice Pillow's own limit: the size is in its message
            raise _over_limit(_pixels(int(m.group(1))) if m else "too many pixels") from None
        except Exception as exc:
            raise TextureError(f"cannot be read ({' '.join(str(exc).split())})") from None
        with im:
            w, h = im.size
            if w * h > MAX_TEXTURE_PIXELS:
                raise _too_large(w, h)
            try:
                im.load()  # a truncated file fails here, not later
                values = _channel01(im, channel)
            except Exception as exc:
                raise TextureError(f"cannot be read ({' '.join(str(exc).split())})") from None
            wide = im.mode in ("I;16", "I;16B", "I;16L", "I", "F")
            srgb_auto = not wide and (len(im.getbands()) >= 3 or im.mode in ("P", "PA"))
            info = im.info
    return Decoded(values, srgb_auto, _wrap_metadata(info))


def _channel01(im, channel: str) -> np.ndarray:
    """Channel ``channel`` of a Pillow image in [0, 1], float32 [h, w] (8- and 16-bit, palette,
    grey, float): grey images give r = g = b, and a = 1 without alpha."""
    if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        if channel == "a":
            return np.ones((im.size[1], im.size[0]), np.float32)
        if im.mode == "F":
            return np.clip(np.asarray(im, dtype=np.float32), 0.0, 1.0)
        a = np.asarray(im, dtype=np.float64)
        top = 65535.0 if im.mode.startswith("I;16") or a.max(initial=0) > 255 else 255.0
        return np.clip(a / top, 0.0, 1.0).astype(np.float32)
    rgba = im if im.mode == "RGBA" else im.convert("RGBA")
    band = rgba.getchannel(CHANNELS.index(channel))
    return np.asarray(band, dtype=np.float32) / 255.0


def _decode_exr(data: bytes, channel: str, path: str | None) -> Decoded:
    import OpenEXR

    tmp = None
    if path is None or not os.path.isfile(path):  # inside a package: OpenEXR reads files only
        fd, tmp = tempfile.mkstemp(suffix=".exr")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        path = tmp
    try:
        try:
            with OpenEXR.File(path, header_only=True) as f:  # the header's values live as long as the file
                header = f.header()
                lo, hi = (np.asarray(c).tolist() for c in header["dataWindow"])
                meta = {k: v for k, v in header.items() if isinstance(v, str)}
            w, h = int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
            if w * h > MAX_TEXTURE_PIXELS:
                raise _too_large(w, h)
            with OpenEXR.File(path, separate_channels=True) as f:
                chans = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
        except TextureError:
            raise
        except Exception as exc:
            raise TextureError(f"cannot be read ({' '.join(str(exc).split())})") from None
    finally:
        if tmp is not None:
            os.remove(tmp)
    colour = [k for k in chans if k not in ("A", "a")]
    alpha = chans.get("A", chans.get("a"))
    if channel == "a":
        plane = alpha if alpha is not None else np.ones((h, w), np.float32)
    elif all(c in chans for c in "RGB"):
        plane = chans["RGB"[CHANNELS.index(channel)]]
    elif "Y" in chans:
        plane = chans["Y"]
    elif len(colour) == 1:
        plane = chans[colour[0]]
    else:
        raise TextureError(f"has channels {', '.join(sorted(chans))}: no R G B, Y or single channel to read {channel} from")
    return Decoded(np.asarray(plane, np.float32), False, _wrap_metadata(meta))


def _wrap_metadata(info: dict) -> tuple[str | None, str | None]:
    """wrapS / wrapT from an image's metadata: ``wrapS`` and ``wrapT`` fields (the spec's), else a
    ``wrapmodes`` field ``"s,t"`` (OpenEXR's and OpenImageIO's; ``periodic`` is repeat)."""
    alias = {"periodic": "repeat"}

    def token(v):
        v = str(v).strip()
        v = alias.get(v, v)
        return v if v in WRAP_NAMES else None

    s, t = info.get("wrapS"), info.get("wrapT")
    if s is None and t is None and isinstance(info.get("wrapmodes"), str):
        parts = info["wrapmodes"].split(",")
        s, t = parts[0], parts[-1]
    return (token(s) if s is not None else None, token(t) if t is not None else None)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve, decoded (float32)."""
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / np.float32(12.92), ((x + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)).astype(np.float32)


def _rotation(degrees: float) -> np.ndarray:
    """The counter-clockwise rotation by ``degrees``, exact at multiples of 90."""
    q, r = divmod(float(degrees), 90.0)
    if r == 0.0:
        c, s = ((1, 0), (0, 1), (-1, 0), (0, -1))[int(q) % 4]
    else:
        a = math.radians(degrees)
        c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]], np.float64)


def _read_asset(resolved: str) -> bytes | None:
    """The bytes of a resolved asset path (a file, or a file inside a package such as
    ``scene.usdz[textures/a.png]``), read through USD's asset resolver; None when absent."""
    from pxr import Ar

    try:
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    except Exception:
        return None
    if asset is None:
        return None
    buf = asset.GetBuffer()
    return None if buf is None else bytes(buf)


def _fmt(v) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")" if isinstance(v, (tuple, list, np.ndarray)) else f"{float(v):g}"


class OpacityNetwork:
    """The opacity networks of one stage's materials, and the textures they read (decoded once each)."""

    def __init__(self, ctx: StageContext):
        self.ctx = ctx
        self.textures: list[Texture] = []
        self.texture_index: dict[tuple, int] = {}

    # ------------------------------------------------------------------ inputs

    def source(self, shader, name: str):
        """What feeds input ``name`` of ``shader``: ``("node", shader, output name)`` for a node's
        output, ``("value", value, attribute)`` for an authored value (the input's own, or an
        interface input's it connects to), ``("none", None, None)`` when nothing is authored."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        inp = shader.GetInput(name)
        if not inp:
            return ("none", None, None)
        attrs = inp.GetValueProducingAttributes(False)
        if not attrs:
            conns = inp.GetAttr().GetConnections()
            if conns:
                self.ctx.warn(shader.GetPrim(), f"inputs:{name} connects to {conns[0]}, which does not exist; its fallback is used")
            return ("none", None, None)
        if len(attrs) > 1:
            self.ctx.warn(shader.GetPrim(), f"inputs:{name} has {len(attrs)} sources; the first, {attrs[0].GetPath()}, is used")
        a = attrs[0]
        if UsdShade.Output.IsOutput(a):
            out = UsdShade.Output(a)
            return ("node", UsdShade.Shader(out.GetPrim()), out.GetBaseName())
        v = self.ctx.get(a)
        return ("value", v, a) if v is not None else ("none", None, None)

    def value(self, shader, name: str, default, src=None):
        """The value of input ``name`` (``default`` when unauthored; ``src``: its :meth:`source`,
        when known). A node output feeding it (an input the spec makes interface-only, or one wsoft
        evaluates only as a value) is a warning, and ``default``; a non-finite number is an error
        naming the node and the input."""
        kind, v, _ = self.source(shader, name) if src is None else src
        if kind == "node":
            shown = repr(default) if isinstance(default, str) else _fmt(default)
            self.ctx.warn(shader.GetPrim(), f"inputs:{name} is connected to node {v.GetPath()}, which wsoft evaluates only as a value; "
                          f"{shown} is used")
            return default
        if kind == "none":
            return default
        if isinstance(default, (float, tuple)):
            vals = np.atleast_1d(np.asarray(v, np.float64)).tolist()
            if not all(math.isfinite(x) for x in vals):
                raise self.ctx.err(shader.GetPrim(), f"inputs:{name} = {_fmt(vals)} is not finite")
            return float(vals[0]) if isinstance(default, float) else tuple(vals)
        return v

    def node_id(self, shader) -> str | None:
        return shader.GetShaderId() if shader else None

    # ------------------------------------------------------------------ opacity

    def read(self, surface, mat: Material) -> None:
        """Fill ``mat``'s opacity from the ``UsdPreviewSurface`` ``surface``: ``opacity_threshold``,
        and a constant ``opacity`` or an opacity ``texture`` (or UDIM tiles) with its ``st`` map."""
        mat.opacity_threshold = self.value(surface, "opacityThreshold", 0.0)
        src = self.source(surface, "opacity")
        kind, node, channel = src
        if kind != "node":
            mat.opacity = self.value(surface, "opacity", 1.0, src)
            if mat.opacity < 1.0 and mat.opacity_threshold <= 0.0:
                self.ctx.warn(surface.GetPrim(), f"constant opacity {mat.opacity:g} (translucency): opaque for every technique but salzman "
                              "(its transparency component)")
            return
        nid = self.node_id(node)
        if nid != "UsdUVTexture":
            self.ctx.warn(node.GetPrim(), f"opacity comes from node {node.GetPath()} ({nid or 'no info:id'}), which wsoft cannot evaluate "
                          "(it reads UsdUVTexture, UsdTransform2d, UsdPrimvarReader_float2); opaque")
            return
        if channel not in CHANNELS:
            self.ctx.warn(node.GetPrim(), f"opacity reads outputs:{channel} of UsdUVTexture {node.GetPath()}, not one channel (r, g, b, a); opaque")
            return
        if mat.opacity_threshold <= 0.0:
            self.ctx.warn(surface.GetPrim(), "textured opacity without opacityThreshold (translucency) is not modelled; opaque")
            return
        self.read_texture(node, channel, mat)

    def read_texture(self, node, channel: str, mat: Material) -> None:
        """The ``UsdUVTexture`` ``node``'s output ``channel`` as ``mat``'s opacity."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        c = CHANNELS.index(channel)
        fallback = self.value(node, "fallback", (0.0, 0.0, 0.0, 1.0))[c]
        scale = self.value(node, "scale", (1.0, 1.0, 1.0, 1.0))[c]
        bias = self.value(node, "bias", (0.0, 0.0, 0.0, 0.0))[c]
        wraps = tuple(str(self.value(node, nm, "useMetadata")) for nm in ("wrapS", "wrapT"))
        for nm, w in zip(("wrapS", "wrapT"), wraps):
            if w not in WRAP_NAMES and w != "useMetadata":
                self.ctx.warn(node.GetPrim(), f"inputs:{nm} = {w!r} is not a wrap mode (black, clamp, repeat, mirror, useMetadata); useMetadata")
        wraps = tuple(w if w in WRAP_NAMES else "useMetadata" for w in wraps)
        space = str(self.value(node, "sourceColorSpace", "auto"))
        if space not in ("raw", "sRGB", "auto"):
            self.ctx.warn(node.GetPrim(), f"inputs:sourceColorSpace = {space!r} is not raw, sRGB or auto; auto")
            space = "auto"
        mat.fallback = fallback
        mat.opacity = fallback  # until a texture is read
        st = self.st_map(node)
        if st is None:
            mat.opacity = 1.0
            return
        kind, asset, attr = self.source(node, "file")
        what = f"opacity is its fallback {channel} = {fallback:g} ({'opaque' if fallback >= mat.opacity_threshold else 'cut away'})"
        if kind == "node":
            self.ctx.warn(node.GetPrim(), f"inputs:file is connected to node {asset.GetPath()}, not an asset; {what}")
            return
        if asset is not None and not isinstance(asset, Sdf.AssetPath):
            self.ctx.warn(node.GetPrim(), f"inputs:file is a {type(asset).__name__}, not an asset path; {what}")
            return
        if asset is None or not asset.path:
            self.ctx.warn(node.GetPrim(), f"UsdUVTexture has no file; {what}")
            return
        spec = (channel, scale, bias, space)
        if UsdShade.UdimUtils.IsUdimIdentifier(asset.path):
            tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(asset.path, self._layer_of(attr))
            if not tiles:
                self.ctx.warn(node.GetPrim(), f"no tile of the UDIM texture {asset.path!r} found; {what}")
                return
            mat.udim = {}
            for resolved, tile in tiles:
                label = UsdShade.UdimUtils.ReplaceUdimPattern(asset.path, str(tile))
                path = resolved.resolvedPath if isinstance(resolved, Sdf.AssetPath) else str(resolved)
                mat.udim[int(tile)] = self.texture(node, label, path, spec, ("clamp", "clamp"), what)
            mat.st, mat.opacity = st, 1.0
            return
        idx = self.texture(node, asset.path, asset.resolvedPath or "", spec, wraps, what)
        if idx >= 0:
            mat.texture, mat.st = idx, st

    def _layer_of(self, attr):
        """The layer whose opinion gives ``attr`` its value (UDIM paths are anchored to it)."""
        for spec in attr.GetPropertyStack(self.ctx.timecode):
            if spec.HasDefaultValue() or spec.layer.GetNumTimeSamplesForPath(spec.path):
                return spec.layer
        return self.ctx.stage.GetRootLayer()

    def texture(self, node, label: str, resolved: str, spec: tuple, wraps: tuple[str, str], what: str) -> int:
        """The texture index of file ``resolved`` (named ``label``) read as ``spec`` = (channel,
        scale, bias, colour space) with ``wraps``; -1 (a warning ending with ``what``) when it
        cannot be read."""
        channel, scale, bias, space = spec
        key = (resolved or label, spec, wraps)
        if key in self.texture_index:
            return self.texture_index[key]
        data = _read_asset(resolved) if resolved else None  # through USD's asset resolver: files inside a .usdz too
        if data is None:
            self.ctx.warn(node.GetPrim(), f"texture {label!r} not found; {what}")
            return -1
        try:
            img = decode(data, channel, resolved)
        except TextureError as exc:
            self.ctx.warn(node.GetPrim(), f"texture {label!r} {exc}; {what}")
            return -1
        values = img.values
        bad = ~np.isfinite(values)
        if bad.any():
            self.ctx.warn(node.GetPrim(), f"texture {label!r}: {int(bad.sum())} texels of {channel} are not finite (NaN or inf); read as 0")
            values = np.where(bad, np.float32(0.0), values)
        if channel != "a" and (space == "sRGB" or space == "auto" and img.srgb_auto):
            values = srgb_to_linear(values)
        if (scale, bias) != (1.0, 0.0):
            values = (values * np.float32(scale) + np.float32(bias)).astype(np.float32)
        modes = []
        for w, meta in zip(wraps, img.wraps):
            modes.append(WRAP_NAMES[w] if w != "useMetadata" else WRAP_NAMES.get(meta, WRAP_BLACK))
        tex = Texture(asset=label, data=np.ascontiguousarray(values[::-1], dtype=np.float32), wrap_s=modes[0], wrap_t=modes[1],
                      border=float(np.float32(bias)))  # bottom-up rows: st (0,0) = lower-left
        self.textures.append(tex)
        self.texture_index[key] = len(self.textures) - 1
        return len(self.textures) - 1

    # ------------------------------------------------------------------ st

    def st_map(self, texture) -> StMap | None:
        """Where the texture node ``texture``'s st comes from; None (a warning) when a node on the
        way cannot be evaluated."""
        src = self.source(texture, "st")
        kind, v, _ = src
        if kind != "node":
            st = self.value(texture, "st", (0.0, 0.0), src)
            self.ctx.warn(texture.GetPrim(), f"inputs:st is not connected: every point reads st = {_fmt(st)}")
            return StMap(None, st)
        return self._st_from(v, texture, 0)

    def _st_from(self, node, texture, depth: int) -> StMap | None:
        nid = self.node_id(node)
        if depth > _MAX_CHAIN:
            self.ctx.warn(node.GetPrim(), f"the st of UsdUVTexture {texture.GetPath()} passes through more than {_MAX_CHAIN} nodes "
                          "(a cycle?); opaque")
            return None
        if nid == "UsdPrimvarReader_float2":
            name = str(self.value(node, "varname", ""))
            fallback = self.value(node, "fallback", (0.0, 0.0))
            if not name:
                self.ctx.warn(node.GetPrim(), f"UsdPrimvarReader_float2 has no varname: every point reads its fallback {_fmt(fallback)}")
                return StMap(None, fallback, reader=str(node.GetPath()))
            return StMap(name, fallback, reader=str(node.GetPath()))
        if nid == "UsdTransform2d":
            src = self.source(node, "in")
            if src[0] == "node":
                inner = self._st_from(src[1], texture, depth + 1)
                if inner is None:
                    return None
            else:
                inner = StMap(None, self.value(node, "in", (0.0, 0.0), src))
            rot = self.value(node, "rotation", 0.0)
            scale = self.value(node, "scale", (1.0, 1.0))
            trans = self.value(node, "translation", (0.0, 0.0))
            m = np.eye(3)
            m[:2, :2] = _rotation(rot) @ np.diag(scale)  # in * scale, then rotated, then translated
            m[:2, 2] = trans
            a = np.vstack([np.asarray(inner.matrix, np.float64), [0.0, 0.0, 1.0]])
            t = m @ a
            matrix = tuple(tuple(float(x) for x in row) for row in t[:2])
            return StMap(inner.primvar, inner.fallback, matrix, inner.reader)
        self.ctx.warn(node.GetPrim(), f"the st of UsdUVTexture {texture.GetPath()} comes from node {node.GetPath()} ({nid or 'no info:id'}), "
                      "which wsoft cannot evaluate (it reads UsdPrimvarReader_float2 and UsdTransform2d); opaque")
        return None
