"""Catalogue of model extensions a params file may activate (``extensions: [...]``).

Each name is a candidate cause found by ``battery-predictor diagnose``; the
physics each one adds is implemented in :mod:`battery_predictor.diagnosis.extensions_impl`.
"""

from __future__ import annotations

#: Extension names, in the order the diagnosis reports them.
EXTENSION_NAMES = (
    "temperature",
    "capacity_fade",
    "resistance_growth",
    "current_offset",
    "cell_imbalance",
    "electrolyte_transport",
    "hysteresis",
)
