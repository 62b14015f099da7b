"""``python -m wsoft.usd_scenes``: measure every bundled stage and write ``catalog.json`` (what
``wsoft scenes`` prints without loading the stages)."""

from wsoft.usd_scenes import write_catalog

print(f"wrote {write_catalog()}")
