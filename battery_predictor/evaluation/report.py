"""Markdown report with PNG figures of the Fig. 4, 5, 7, 8 kind and the tables."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from matplotlib.figure import Figure

from battery_predictor.evaluation.paper_eval import PAPER
from battery_predictor.jsonutil import json_default

if TYPE_CHECKING:
    from battery_predictor.evaluation.paper_eval import FitValidation, RouteCase, RuntimePoint
    from battery_predictor.recording import Recording
    from battery_predictor.simulation.base import PackSimResult


def _fmt(x: float | None, nd: int = 2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def fig_fit(rows: Sequence[FitValidation], dynamic: Recording, static: Recording, out: Path,
            base: str = "Chen2020") -> Path | None:
    """Fig. 4 kind: measured vs simulated on both profiles for the model fitted on the dynamic one."""
    row = next((r for r in rows if r.base_parameter_set == base and r.opt_profile == "dynamic"
                and r.opt_result is not None), None)
    if row is None:
        return None
    assert row.opt_result is not None and row.val_result is not None  # table2 sets both or neither
    fig = Figure(figsize=(11, 3.6))
    axes = fig.subplots(1, 2)
    for ax, (label, res, rec, score) in zip(axes, (("dynamic (fit)", row.opt_result, dynamic, row.opt_r2_mod),
                                                   ("static (validation)", row.val_result, static,
                                                    row.val_r2_mod))):
        ax.plot(rec.relative_time_s / 60, rec.voltage_v, "k", lw=1, label="measured")
        ax.plot(res.time_s / 60, res.pack_voltage_v, "r--", lw=1, label="simulated")
        ax.set_ylim(min(rec.voltage_v) - 0.3, max(rec.voltage_v) + 0.3)
        ax.set_title(f"{label}: R2_mod {score:.3f}", fontsize=9)
        ax.set_xlabel("time [min]")
        ax.set_ylabel("pack voltage [V]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Information robot, {base} fitted on the dynamic discharge (cf. paper Fig. 4)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


def fig_runtime(points: Sequence[RuntimePoint], out: Path) -> Path:
    """Fig. 5 kind: predicted vs actual remaining runtime per pack at each checkpoint."""
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    names = list(dict.fromkeys(p.recording for p in points))
    for k, name in enumerate(names):
        sub = [p for p in points if p.recording == name]
        c = f"C{k}"
        ax.plot([p.elapsed_s / 60 for p in sub], [p.actual_remaining_s / 60 for p in sub], "-", color=c, lw=1)
        ax.plot([p.elapsed_s / 60 for p in sub], [p.predicted_remaining_s / 60 for p in sub], "o", color=c,
                label=Path(name).name)
    ax.set_xlabel("elapsed runtime [min]")
    ax.set_ylabel("remaining runtime [min]")
    ax.set_title("Remaining runtime: predicted (dots) vs actual (lines) (cf. paper Fig. 5)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


def fig_stepwise(rec: Recording, res: PackSimResult, score: float, out: Path) -> Path:
    """Fig. 7 kind: luggage robot stepwise experiment, measured vs fitted model."""
    fig = Figure(figsize=(9, 3.6))
    ax = fig.subplots()
    ax.plot(rec.relative_time_s / 60, rec.voltage_v, "k", lw=1, label="measured")
    ax.plot(res.time_s / 60, res.pack_voltage_v, "r--", lw=1, label="simulated")
    ax.set_ylim(min(rec.voltage_v) - 0.5, max(rec.voltage_v) + 0.5)
    ax.set_xlabel("time [min]")
    ax.set_ylabel("pack voltage [V]")
    ax.set_title(f"Luggage robot stepwise experiment: R2_mod {score:.3f} (cf. paper Fig. 7)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


def fig_routes(cases: Sequence[RouteCase], threshold_v: float, out: Path) -> Path:
    """Fig. 8 kind: predicted vs recorded voltage at 1.70 A after cycle 1 and 2, per payload."""
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    for k, c in enumerate(cases):
        x = [1 + 0.02 * k, 2 + 0.02 * k]
        ax.plot(x, c.actual_v, "o-", color=f"C{int(c.payload_kg) // 20 - 1}", lw=0.8)
        ax.plot(x, c.predicted_v, "x--", color=f"C{int(c.payload_kg) // 20 - 1}", lw=0.8)
    for payload in (20, 40, 60, 80):
        ax.plot([], [], "s", color=f"C{payload // 20 - 1}", label=f"{payload} kg")
    ax.plot([], [], "ko-", label="recorded")
    ax.plot([], [], "kx--", label="predicted")
    ax.axhline(threshold_v, color="r", lw=1, label=f"threshold {threshold_v:.2f} V")
    ax.set_xticks([1, 2], ["after cycle 1", "after cycle 2"])
    ax.set_ylabel("pack voltage at 1.70 A [V]")
    ax.set_title("Luggage robot: voltage after each longest-route cycle (cf. paper Fig. 8)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


def write_markdown(out_dir: Path, summary: dict, figures: Mapping[str, Path | None]) -> Path:
    """The report: tables with the paper's figures beside ours, and the figures."""
    lines = ["# Evaluation as in the seed paper (section 5)", "",
             "All recordings are the bundled **emulated** ones unless other files were given "
             "(see `bags/README.md`).", ""]
    settings = summary.get("settings")
    if settings:
        lines += ["Settings: " + ", ".join(f"{k} `{v}`" for k, v in settings.items()) + ".", ""]
    if "table2" in summary:
        lines += _table2_lines(summary["table2"])
    if "runtime" in summary:
        lines += _runtime_lines(summary["runtime"], summary.get("runtime_peaks"))
    if "stepwise" in summary:
        lines += ["## Luggage robot: stepwise experiment fit (5.2.3)", "",
                  f"R2_mod {_fmt(summary['stepwise']['r2_mod'], 3)} (paper: {PAPER['ranger_stepwise_r2_mod']}).", ""]
        if summary["stepwise"].get("weak_group"):
            lines += [f"Fitted params: {summary['stepwise']['weak_group']}.", ""]
    if "routes" in summary:
        lines += _routes_lines(summary["routes"], summary.get("route_cases"))
    for title, path in figures.items():
        if path is not None:
            lines += [f"![{title}]({path.name})", ""]
    out = out_dir / "report.md"
    out.write_text("\n".join(lines))
    (out_dir / "summary.json").write_text(json.dumps(summary, default=json_default, indent=1, allow_nan=True))
    return out


def _table2_lines(table2: Sequence[dict]) -> list[str]:
    """Table 2: optimisation and validation R2_mod beside the paper's."""
    lines = ["## Information robot: optimisation and validation (Table 2)", "",
             "| opt. profile | parameter set | opt. R2_mod | val. R2_mod | paper opt. | paper val. |",
             "|---|---|---|---|---|---|"]
    for r in table2:
        p = PAPER["table2"].get((r["opt_profile"], r["base_parameter_set"]), (None, None))
        lines.append(f"| {r['opt_profile']} | {r['base_parameter_set']} | {_fmt(r['opt_r2_mod'])} | "
                     f"{_fmt(r['val_r2_mod'])} | {_fmt(p[0])} | {_fmt(p[1])} |")
    lines.append("")
    return lines


def _runtime_lines(rt: dict, pk: dict | None) -> list[str]:
    """The remaining-runtime table (5.1.6), with the load-peak columns when ``pk`` is given."""
    lines = ["## Information robot: remaining runtime (5.1.6)", "",
             "Paper strategy: simulate the present cycle's average current until 13.30 V. "
             + ("Predictor default (beyond the paper): the robot stops at the first measured 5 s window below "
                "the cut-off, which falls on a load peak; the runtime ends where a peak (the "
                f"{pk['peak_current_quantile']} quantile of the cycle's 5 s currents) drawn from the "
                "average-load trajectory meets the cut-off." if pk else ""), "",
             "| recording | MAE [min] | MAPE [%] | checkpoints |"
             + (" MAE with peaks [min] | MAPE with peaks [%] |" if pk else ""),
             "|---|---|---|---|" + ("---|---|" if pk else "")]
    for name, v in rt["per_recording"].items():
        extra = ""
        if pk:
            w = pk["per_recording"].get(name, {})
            extra = f" {_fmt(w.get('mae_min'))} | {_fmt(w.get('mape_pct'))} |"
        lines.append(f"| {Path(name).name} | {_fmt(v['mae_min'])} | {_fmt(v['mape_pct'])} | {v['points']} |"
                     + extra)
    lines.append(f"| **overall** | **{_fmt(rt['mae_min'])}** | **{_fmt(rt['mape_pct'])}** | |"
                 + (f" **{_fmt(pk['mae_min'])}** | **{_fmt(pk['mape_pct'])}** |" if pk else ""))
    lines.append(f"| paper | {PAPER['runtime_mae_min']} | {PAPER['runtime_mape_pct']} | |" + (" | |" if pk else ""))
    lines += ["", f"Mean signed error {_fmt(rt.get('bias_min'))} min (positive: predicted too long) over a mean "
              f"actual remaining runtime of {_fmt(rt.get('mean_actual_remaining_min'), 1)} min; the MAE grows "
              "with the length of the discharges, the MAPE is the figure comparable with the paper's."
              + (f" With peaks: mean signed error {_fmt(pk.get('bias_min'))} min." if pk else ""), ""]
    return lines


def _routes_lines(r: dict, cases: Sequence[dict] | None) -> list[str]:
    """The voltage after the longest route (5.2.4), its decisions, and one row per recording."""
    lines = ["## Luggage robot: voltage after the longest route (5.2.4)", "",
             "| | MAE [V] | MAPE [%] | bias cycle 1 [V] | bias cycle 2 [V] |", "|---|---|---|---|---|",
             f"| ours | {_fmt(r['mae_v'])} | {_fmt(r['mape_pct'])} | {_fmt(r['bias_v_cycle1'])} | "
             f"{_fmt(r['bias_v_cycle2'])} |",
             f"| paper | {PAPER['route_mae_v']} | {PAPER['route_mape_pct']} | overestimated | underestimated |",
             "", f"Decisions (one more longest route, asked at the start, after cycle 1 and after cycle 2): "
             f"{r['decisions_correct']} of {r['decisions']} match the truth; {r['unsafe_accepts']} unsafe "
             "accepts (accepted although the recorded voltage fell below the threshold).", ""]
    if cases:
        lines += ["| recording | payload [kg] | predicted / recorded after cycle 1 [V] | after cycle 2 [V] | "
                  "decisions (ours / truth) |", "|---|---|---|---|---|"]
        for c in cases:
            dec = "".join("A" if d else "R" for d in c["decisions"])
            tru = "".join("A" if d else "R" for d in c["truth"])
            lines.append(f"| {Path(c['recording']).name} | {c['payload_kg']:.0f} | {_fmt(c['predicted_v'][0])} / "
                         f"{_fmt(c['actual_v'][0])} | {_fmt(c['predicted_v'][1])} / {_fmt(c['actual_v'][1])} | "
                         f"{dec} / {tru} |")
        lines.append("")
    return lines
