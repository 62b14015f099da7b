"""``wsoft bake``: a technique's visibility baked into a USD layer of overs (primvars, textures)."""

from __future__ import annotations

import os
import sys
import time

import wsoft.cli.args as a
from wsoft.cli.common import check_args, check_output, compile_note, parse_sets, print_notes, print_warnings
from wsoft.cli.progress import CompileNotice


def add_parser(sub, one_of: str) -> None:
    k = sub.add_parser("bake", help="bake a technique's visibility into a USD layer of overs (primvars, optional textures)",
                       formatter_class=a.Help, description="Writes OUT, a layer to add as a sublayer of the stage: on every mesh a "
                       "float primvar primvars:wsoft:visibility:<light> (vertex, or faceVarying on meshes with creases), time-sampled "
                       "over --frames, computed at the vertices themselves (seen by a camera or not); with --texture-size, an EXR per "
                       "mesh and light over its st and a UsdUVTexture hookup under <mesh>/wsoftVisibility.")
    a.scene(k, "a .usda/.usdc/.usdz file or a bundled stage's name (lightmapped_bridge)")
    k.add_argument("--technique", "-t", required=True, metavar="TECHNIQUE", help=one_of + " (izb with --set aa=none; ssm without a budget_map)")
    a.sets(k)
    a.light(k, "light path or name (default: every shadow-casting light the technique supports)")
    a.frames(k, "time codes A to B inclusive (step 1, or STEP), or one time code A, within the stage's range: time samples "
             "(default: the time render uses, written as default values)")
    k.add_argument("--out", required=True, help="the layer to write (.usda, .usdc or .usd)")
    k.add_argument("--texture-size", type=a.int_in("--texture-size", 1, 8192), metavar="N", help="also bake an N x N texture per mesh with st and light, "
                   "N from 1 to 8192")
    k.add_argument("--texture-dir", help="where the textures go (default: the layer's folder)")
    k.add_argument("--crease-angle", type=a.float_in("--crease-angle", 0.0, 180.0), default=30.0, metavar="DEGREES", help="faces around a vertex closer "
                   "than this (0 to 180) share its normal; farther ones make the mesh faceVarying")
    a.device(k)
    a.subdiv(k)
    a.material_purpose(k)
    k.set_defaults(fn=run)


def run(args) -> int:
    """Bake a technique's visibility into a layer of overs (primvars, optional textures)."""
    from wsoft.errors import ParameterError
    from wsoft.params import parse_frames

    check_output(args.out, "--out")
    if not args.out.endswith((".usda", ".usdc", ".usd")):
        raise ParameterError(f"--out {args.out}: the layer must be a .usda, .usdc or .usd file")
    frames = None
    if args.frames is not None:
        try:
            frames = parse_frames(args.frames)
        except ValueError as exc:
            raise ParameterError(f"--frames {exc}") from None
    if args.texture_dir:
        check_output(args.texture_dir, "--texture-dir", folder=True)
    scene_file = check_args(args, [args.technique])
    import wsoft

    params = parse_sets(args.set, [args.technique])
    stats: dict = {}
    t0 = time.perf_counter()

    def progress(done, total, t):
        if total > 1:
            f = stats["frames"][-1]
            print(f"frame {t:g} ({done}/{total}): {f['total_ms'] / 1e3:.2f} s", file=sys.stderr)

    with CompileNotice(args.device, [args.technique]):
        wsoft.bake(scene_file, args.technique, light=args.light, frames=frames, out=args.out, texture_size=args.texture_size,
                   texture_dir=args.texture_dir, device=args.device, crease_angle=args.crease_angle, stats=stats, progress=progress,
                   subdiv_level=args.subdiv_level, material_purpose=args.material_purpose, **params)
    wall = time.perf_counter() - t0
    print_warnings(stats["warnings"])
    print_notes(stats["notes"])
    fr = stats["frames"]
    per = sum(f["total_ms"] for f in fr) / len(fr) / 1e3
    comp = sum(f["compile_ms"] for f in fr)
    kinds = {}
    for m in stats["meshes"].values():
        kinds[m["interpolation"]] = kinds.get(m["interpolation"], 0) + 1
    print(f"{args.technique} on {os.path.basename(scene_file)}: {len(stats['meshes'])} meshes "
          f"({', '.join(f'{n} {k}' for k, n in sorted(kinds.items()))}), {fr[0]['points']} points, lights "
          f"{', '.join(stats['lights'].values())}, {len(fr)} frame(s): {per:.2f} s per frame{compile_note(comp)}; {wall:.1f} s in all")
    print(f"wrote {args.out}" + (f" and {len(stats['textures'])} texture(s)" if stats["textures"] else ""))
    return 0
