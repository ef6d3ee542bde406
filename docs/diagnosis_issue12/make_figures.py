"""Figures of docs/findings.md section 0b: measured vs baseline vs candidates, residuals with the measured temperature.

Usage (the pickles are written by an in-process ``diagnose()`` run, see docs/findings.md)::

    .venv/bin/python docs/diagnosis_issue12/make_figures.py DIAG.pkl OUT.png [CAUSE ...]
"""

from __future__ import annotations

import pickle
import sys

import numpy as np
from matplotlib.figure import Figure


def main(path: str, out: str, causes: list[str]) -> None:
    with open(path, "rb") as fh:
        diag = pickle.load(fh)
    results = [diag.baseline] + [c for c in diag.candidates if c.sims and (not causes or c.cause in causes)]
    n = len(diag.observed)
    fig = Figure(figsize=(13, 3.6 * n))
    axes = fig.subplots(n, 2, squeeze=False)
    for k, obs in enumerate(diag.observed):
        ax_v, ax_r = axes[k]
        ax_v.plot(obs.t, obs.v, "k-", lw=0.8, label="measured")
        for res in results:
            sim = res.sims[k]
            label = "baseline" if res.cause == "none" else res.cause
            ax_v.plot(sim.t, sim.v_pack, lw=0.7, label=label)
            ax_r.plot(sim.t, sim.v_pack - np.interp(sim.t, obs.t, obs.v), lw=0.7, label=label)
        for ax in (ax_v, ax_r):
            ax.axvline(obs.t_split, color="0.5", ls="--", lw=0.8)
            ax.set_xlabel("time (s)")
        ax_v.set_ylabel("voltage (V)")
        ax_r.set_ylabel("model - measured (V)")
        ax_r.set_ylim(-0.4, 0.4)
        ax_v.set_title(f"{obs.name.split('/')[-1]} (held out right of the dashed line)", fontsize=9)
        if obs.temperature_k is not None:
            ax_t = ax_r.twinx()
            ax_t.plot(obs.t, obs.temperature_k - 273.15, "r:", lw=0.9)
            ax_t.set_ylabel("measured temperature (degC, dotted)", color="r")
        ax_v.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=80)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
