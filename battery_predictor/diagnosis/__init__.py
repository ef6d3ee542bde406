"""Diagnosis: what the simulation gets wrong, the cause, and the model extension that fixes it.

- :mod:`~battery_predictor.diagnosis.diagnose`: the procedure (reference fit, equal-budget fits of the
  baseline and each candidate on the first part of the observed data, held-out judgement, decision).
- :mod:`~battery_predictor.diagnosis.candidates`: one small class per cause (its extra parameters and
  bounds, how it simulates, how it writes a params file).
- :mod:`~battery_predictor.diagnosis.engine`: re-solvable PyBaMM builds with every fitted value an
  ``[input]`` (the baseline equals the fast pack simulator).
- :mod:`~battery_predictor.diagnosis.residuals`: the baseline residual against time, SOC, charge,
  current, temperature and direction of recent current; the evidence text.
- :mod:`~battery_predictor.diagnosis.scoring`, :mod:`~battery_predictor.diagnosis.lsq`: held-out scores,
  noise level, budgeted least squares.
- :mod:`~battery_predictor.diagnosis.report`: Markdown report and figures.

What an active extension changes in the model used by ``simulate``, ``fit`` and the predictor is
:mod:`battery_predictor.simulation.extensions`.
"""
