"""``wsoft techniques``: every technique, its passes and parameters (``--json``, ``--markdown``)."""

from __future__ import annotations

import json

import wsoft.cli.args as a


def add_parser(sub, one_of: str) -> None:
    t = sub.add_parser("techniques", help="techniques and their parameters", formatter_class=a.Help)
    t.add_argument("--json", action="store_true", help="every technique's description as JSON")
    t.add_argument("--markdown", action="store_true", help="the README's technique table")
    t.set_defaults(fn=run)


def run(args) -> int:
    from wsoft.techniques import TECHNIQUES, markdown_table

    if args.markdown:
        print(markdown_table())
        return 0
    desc = [TECHNIQUES[n].describe() for n in sorted(TECHNIQUES)]
    if args.json:
        print(json.dumps(desc, indent=2, default=str))
        return 0
    for d in desc:
        print(f"{d['name']}: {d['summary']}")
        print(f"  reads: {', '.join(d['reads'])}; writes: {', '.join(d['writes'])}")
        for spec in TECHNIQUES[d["name"]].passes:
            print(f"  pass {spec.text()}")
        for p in d["parameters"]:
            rng = f" [{p['range']}]" if p["range"] else ""
            print(f"  {p['name']:<16} {p['type']:<6} default {p['default']!s:<8} {p['meaning']}{rng}")
        for q in d["quality"]:
            print(f"  quality: {q['param']} over {', '.join(map(str, q['values']))} ({q['note']})")
        if d["cylinder_light"]:
            print(f"  cylinder light: {d['cylinder_light']}")
    return 0
