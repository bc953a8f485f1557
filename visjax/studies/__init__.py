"""Generic studies over any estimator: sweeps, gain tuning, comparisons (to come).

The papers' own experiments live in `visjax.papers`.
"""
