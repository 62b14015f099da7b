"""Benchmark sweeps (``wsoft bench SWEEP``): rows in ``reports/<sweep>.jsonl``, report in ``reports/<sweep>.md``."""
