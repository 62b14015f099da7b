"""``wsoft scenes``: the bundled stages, what each shows (``--json``)."""

from __future__ import annotations

import json

import wsoft.cli.args as a


def add_parser(sub, one_of: str) -> None:
    s = sub.add_parser("scenes", help="the bundled stages: triangles, lights, frames and what each shows", formatter_class=a.Help)
    s.add_argument("--json", action="store_true", help="the list as JSON")
    s.set_defaults(fn=run)


def _light_kinds(lights: list) -> str:
    """``[[name, kind], ...]`` as ``rect, 2 sphere``: each kind once, in order, with its count."""
    counts: dict[str, int] = {}
    for _, kind in lights:
        counts[kind] = counts.get(kind, 0) + 1
    return ", ".join(k if n == 1 else f"{n} {k}" for k, n in counts.items()) or "-"


def run(args) -> int:
    """The bundled stages: name, triangles, shadow-casting lights, frames and what each shows, from
    ``wsoft.usd_scenes.ABOUT`` and its catalog (a stage missing from the catalog is read)."""
    from wsoft import usd_scenes

    cat = usd_scenes.catalog()
    missing = [n for n in usd_scenes.names() if n not in cat]
    if missing:  # stages added since the catalog was written: read them
        from wsoft.scene.catalog import measure

        cat = {**cat, **{n: measure(n) for n in missing}}
    entries = {n: {**cat[n], "about": usd_scenes.ABOUT.get(n, "")} for n in usd_scenes.names()}
    if args.json:
        print(json.dumps(entries, indent=2))
        return 0
    lights = {n: _light_kinds(e["lights"]) for n, e in entries.items()}
    w, lw = max(map(len, entries)), max(map(len, lights.values()))
    print(f"{'name':<{w}}  {'triangles':>10}  {'lights':<{lw}}  {'frames':<6}  what it shows")
    for n, e in entries.items():
        frames = f"{e['frames'][0]:g}-{e['frames'][1]:g}" if e["frames"] else ""
        print(f"{n:<{w}}  {e['triangles']:>10,}  {lights[n]:<{lw}}  {frames:<6}  {e['about']}")
    print(f"\nA name works wherever a stage file does (wsoft render box_plane -t pcss); the files are in {usd_scenes.folder()}.")
    return 0
