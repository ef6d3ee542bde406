"""What each model extension (see :mod:`battery_predictor.extensions`) changes in the PyBaMM model.

Extensions that are PyBaMM model options return them here; extensions that act on
parameters or the load (capacity fade, current offset, cell imbalance) are applied
by the diagnosis and stored as fitted values in the params file.
"""

from __future__ import annotations

_OPTIONS = {
    "temperature": {"thermal": "lumped"},
    "resistance_growth": {"contact resistance": "true"},
}


def extension_model_options(params) -> dict:
    """PyBaMM model options implied by the params' active extensions."""
    opts: dict = {}
    for ext in params.extensions:
        opts.update(_OPTIONS.get(ext, {}))
    return opts
