"""Procedural organic geometry for the paper-analog scenes: swept tubes, creatures and plants.

All of it is swept tubes and curved leaf strips displaced by smooth, seeded sums of sinusoids, so
the same arguments give the same mesh on every run.
"""
