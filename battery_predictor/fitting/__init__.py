"""Fitting composed like PyBOP: a simulator, a cost (R2_mod), a problem, an optimiser (TPE).

- :mod:`~battery_predictor.fitting.cost`: the modified R2 of the seed paper, Eq. (1)-(3).
- :mod:`~battery_predictor.fitting.space`: fit parameters and their bounds.
- :mod:`~battery_predictor.fitting.problem`: recordings + params + simulator -> score of a candidate.
- :mod:`~battery_predictor.fitting.optimiser`: seeded Optuna TPE over a problem, RDB storage.
- :mod:`~battery_predictor.fitting.screening`: the +10 % sensitivity screening (paper step 4).
"""
