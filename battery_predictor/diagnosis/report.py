"""Diagnosis report: Markdown with the verdict, the candidate table and the figures that carry the evidence.

Files written into the report directory:

``report.md``          verdict, evidence, the candidate table, the reference fit, how to read it;
``voltage.png``        measured vs baseline vs extended voltage of each observed recording (fit part and
                       held-out part marked) and both residuals;
``residuals.png``      the baseline residual against time, SOC, charge throughput, current, temperature
                       and the direction of recent current (eta^2 in each title);
``candidates.png``     held-out RMSE of the baseline and of every candidate.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from battery_predictor.diagnosis.residuals import _LABELS, FEATURES

if TYPE_CHECKING:
    from battery_predictor.diagnosis.reference import ReferenceFit
    from battery_predictor.diagnosis.results import Diagnosis

_UNITS = {"time": "h", "soc": "-", "charge_throughput": "Ah", "current": "A", "temperature": "K",
          "direction": "-1 charge / 0 rest / +1 discharge"}


def _fmt(v: float | None, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{digits}f}"


def _figure(figsize: tuple[float, float]) -> Figure:
    """A matplotlib ``Figure`` on the Agg canvas (no pyplot, no global backend)."""
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def plot_voltage(diag: Diagnosis, path: Path) -> Path:
    n = len(diag.observed)
    fig = _figure((11, 5.5 * n))
    axes = fig.subplots(2 * n, 1, sharex=False, squeeze=False)
    ext = diag.extended
    for k, obs in enumerate(diag.observed):
        ax, axr = axes[2 * k, 0], axes[2 * k + 1, 0]
        t_h = obs.t / 3600.0
        ax.plot(t_h, obs.v, ".", color="0.2", ms=2, label="measured")
        models = [("baseline (SPM)", diag.baseline, "C0")]
        if ext is not diag.baseline:
            models.append((f"extended ({ext.cause})", ext, "C3"))
        for label, res, color in models:
            if k < len(res.sims) and res.sims[k].t.size:
                sim = res.sims[k]
                ax.plot(sim.t / 3600.0, sim.v_pack, "-", color=color, lw=1.2, label=label)
                m = min(sim.t.size, obs.t.size)
                axr.plot(t_h[:m], 1e3 * (obs.v[:m] - sim.v_pack[:m]), "-", color=color, lw=0.8,
                         label=f"measured - {label}")
        for a in (ax, axr):
            a.axvline(obs.t_split / 3600.0, color="k", ls="--", lw=0.8)
            a.grid(alpha=0.3)
        ax.set_ylabel("pack voltage (V)")
        ax.set_title(f"{Path(obs.name).name}: fit part left of the dashed line, held out right of it")
        ax.legend(loc="best", fontsize=8)
        axr.set_ylabel("residual (mV)")
        axr.set_xlabel("time (h)")
        axr.axhline(0.0, color="k", lw=0.5)
        axr.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def plot_residuals(diag: Diagnosis, path: Path) -> Path:
    feats = [f for f in FEATURES if f in diag.residuals.eta2]
    cols = 3
    rows = max(1, math.ceil(len(feats) / cols))
    fig = _figure((13, 3.8 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel()[len(feats):]:
        ax.axis("off")
    for ax, f in zip(axes.ravel(), feats):
        for k, s in enumerate(diag.residuals.series):
            x, r = s[f], 1e3 * s["residual_v"]
            if f == "direction":
                x = x + np.random.default_rng(k).uniform(-0.15, 0.15, x.size)
            ax.plot(x, r, ".", ms=2, alpha=0.5, label=Path(diag.observed[k].name).name if k < len(diag.observed)
                    else None)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{_LABELS[f]} ({_UNITS[f]})")
        ax.set_ylabel("measured - baseline (mV)")
        ax.set_title(f"eta2 = {diag.residuals.eta2[f]:.2f}, r = {diag.residuals.pearson_r.get(f, 0.0):+.2f}")
        ax.grid(alpha=0.3)
    fig.suptitle("Baseline residual against the candidate features")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def plot_candidates(diag: Diagnosis, path: Path) -> Path:
    rows = [("none (baseline)", diag.baseline.heldout_rmse_mV)] + [
        (c.cause, c.heldout_rmse_mV) for c in diag.candidates if c.applicable and math.isfinite(c.heldout_rmse_mV)]
    fig = _figure((8, 0.45 * len(rows) + 1.2))
    ax = fig.subplots()
    names = [r[0] for r in rows]
    vals = [r[1] for r in rows]
    colors = ["C3" if n == diag.cause else ("C0" if n.startswith("none") else "0.6") for n in names]
    ax.barh(names, vals, color=colors)
    ax.set_xscale("log")
    ax.invert_yaxis()
    ax.set_xlabel("held-out RMSE (mV, log scale)")
    ax.axvline(diag.noise_mV, color="k", ls=":", lw=0.8, label="voltage noise")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"named cause: {diag.cause}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def write_report(diag: Diagnosis, out_dir: str | Path, command: str = "") -> Path:
    """Write ``report.md`` and its figures into ``out_dir``; returns the Markdown path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not getattr(diag, "judged", True):
        return _write_not_judged(diag, out, command)
    plot_voltage(diag, out / "voltage.png")
    plot_residuals(diag, out / "residuals.png")
    plot_candidates(diag, out / "candidates.png")
    lines = [f"# Diagnosis of `{diag.params.name}`", ""]
    if command:
        lines += ["```", command, "```", ""]
    lines += [f"**Named cause: `{diag.cause}`**" + (f" (held-out RMSE gain {diag.gain_pct:.1f} %)"
                                                     if diag.cause != "none" else ""), "", diag.evidence, ""]
    lines += ["## Held-out scores", "",
              "| model | held-out RMSE (mV) | held-out R2_mod | runtime error (s) |", "|---|---:|---:|---:|",
              f"| baseline | {_fmt(diag.baseline.heldout_rmse_mV)} | {_fmt(diag.baseline.heldout_r2_mod, 4)} | "
              f"{_fmt(diag.baseline.runtime_error_s, 0)} |",
              f"| extended ({diag.extended.cause}) | {_fmt(diag.extended.heldout_rmse_mV)} | "
              f"{_fmt(diag.extended.heldout_r2_mod, 4)} | {_fmt(diag.extended.runtime_error_s, 0)} |", "",
              "![measured, baseline and extended voltage](voltage.png)", "",
              "## Residual of the baseline", "",
              "| feature | eta2 | Pearson r |", "|---|---:|---:|"]
    for f, e in diag.residuals.ranked():
        lines.append(f"| {_LABELS[f]} | {e:.3f} | {diag.residuals.pearson_r.get(f, 0.0):+.3f} |")
    if diag.residuals.collinear:
        lines += ["", "Features that move together in these recordings (not separable): "
                  + ", ".join(f"{_LABELS[a]} / {_LABELS[b]}" for a, b in diag.residuals.collinear) + "."]
    lines += ["", "![baseline residual against the features](residuals.png)", "",
              "## Candidates", "",
              (f"Each candidate fitted its parameters and the initial SOC once per recording (a fold): on every "
               f"other recording whole and the first {100 * diag.fit_fraction:.0f} % of that recording, with "
               f"{diag.budget} model evaluations per fold; each fold predicts the held-out rest of its recording. "
               f"The baseline fitted its initial SOCs alone on the first {100 * diag.fit_fraction:.0f} % of each "
               "recording. Fitted values are the mean over the folds." if diag.split == "recordings" else
               f"Each candidate fitted its parameters and the initial SOC on the first {100 * diag.fit_fraction:.0f} % "
               f"of each recording with {diag.budget} model evaluations, as the baseline did over its initial "
               "SOC alone; all are scored on the held-out rest."), "",
              "| cause | held-out RMSE (mV) | gain (%) | R2_mod | runtime error (s) | fitted |",
              "|---|---:|---:|---:|---:|---|"]
    for c in [diag.baseline] + list(diag.candidates):
        if not c.applicable:
            lines.append(f"| {c.cause} | n/a | n/a | n/a | n/a | not applicable: {c.reason} |")
            continue
        fitted = ", ".join(f"{k} = {v:.4g}" for k, v in c.fitted.items()) or "-"
        if c.unresolved:
            fitted += f" (not named: {c.unresolved})"
        lines.append(f"| {c.cause if c is not diag.baseline else 'none (baseline)'} | {_fmt(c.heldout_rmse_mV)} | "
                     f"{_fmt(c.gain_pct)} | {_fmt(c.heldout_r2_mod, 4)} | {_fmt(c.runtime_error_s, 0)} | {fitted} |")
    lines += ["", "![held-out RMSE of every candidate](candidates.png)", ""]
    if diag.reference is not None:
        lines += _reference_lines(diag.reference)
    lines += [f"Voltage noise estimate: {diag.noise_mV:.1f} mV. Diagnosis time: {diag.seconds:.0f} s.", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path


def _reference_lines(ref: ReferenceFit) -> list[str]:
    per = ", ".join(f"{r:.1f}" for r in getattr(ref, "rmse_mV_per_recording", []))
    lines = ["## Reference fit", "",
             f"Identification (`fit --method identify`) on the {getattr(ref, 'simulator', 'engine')} simulator: RMSE "
             f"{ref.initial_rmse_mV:.1f} -> {ref.rmse_mV:.1f} mV on the reference data"
             + (f" (per recording {per} mV)" if per else "")
             + f", R2_mod {_fmt(getattr(ref, 'r2_mod', float('nan')), 4)} ({ref.evaluations} evaluations, "
             f"{ref.seconds:.0f} s).", ""]
    lines += [f"- `{k}` = {v:.6g}" for k, v in ref.values.items()]
    if ref.skipped:
        lines += ["", "Kept at the params' value: " + ", ".join(f"`{k}`" for k in ref.skipped) + "."]
    lines.append("")
    return lines


def _write_not_judged(diag: Diagnosis, out: Path, command: str) -> Path:
    """``report.md`` of a diagnosis that refused to judge (reference fit too poor): the figure and what to do."""
    lines = [f"# Diagnosis of `{diag.params.name}`", ""]
    if command:
        lines += ["```", command, "```", ""]
    lines += [f"**Not judged** (cause `{diag.cause}`)", "", diag.evidence, ""]
    if diag.reference is not None:
        lines += _reference_lines(diag.reference)
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
