"""The diagnosis's reference fit: the project's identification, and when its result is too poor to judge with.

The baseline of a diagnosis is the params' model fitted on recordings *without* the effect (the
references). That fit is the project's identification (:mod:`battery_predictor.fitting.identification`,
``fit --method identify``): seeded TPE then trust-region least squares in identifiable coordinates
(both electrode capacities, the negative stoichiometry, the series resistance, and each
recording's initial OCV), simulated on the SPM engine
(:class:`~battery_predictor.simulation.engine.EngineSimulator`, ~100x faster than stepping
PyBaMM; models the engine does not cover fall back to the fast simulator with a smaller budget).

A diagnosis is only as good as its reference fit: every candidate is judged against the error the
reference model leaves on healthy data (its *floor*), and an effect is named only when the
baseline's held-out error is several times that floor. When the reference fit itself leaves a large
structural error, every effect drowns in it and naming ``none`` would be a claim the data cannot
support. :func:`reference_verdict` then refuses to judge (see :data:`POOR_EXCESS_MV_PER_CELL`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.fitting.identifiable import TRANSPORT_COORDINATES
from battery_predictor.fitting.identification import DEFAULT_EVALUATIONS
from battery_predictor.params import PackParams, cached_parameter_values
from battery_predictor.recording import Recording, ends_at_cutoff

if TYPE_CHECKING:
    from battery_predictor.fitting.identifiable import Coordinate
    from battery_predictor.fitting.identification import CandidateScore, IdentificationProblem, IdentificationResult
    from battery_predictor.simulation.base import PackSimulator

#: Default evaluation budget of the reference identification on the SPM engine (the ``fit --method
#: identify`` default: the Panasonic 25 degC fit at 1000 evaluations took ~24 s on the engine).
DEFAULT_IDENTIFY_BUDGET = DEFAULT_EVALUATIONS
#: Budget when the engine cannot simulate the params (it falls back to the fast simulator, ~1 s per
#: evaluation of a multi-hour recording).
FALLBACK_BUDGET = 150
#: The reference fit is *poor* when the error it leaves above the voltage noise exceeds this much per
#: cell in series (mV). Physics: between 20 and 80 % SOC the open-circuit voltage of graphite
#: against NMC/NCA cells rises by ~0.35-0.45 V, i.e. 6-7 mV per % SOC; 40 mV per cell is the
#: voltage of a ~6-7 % SOC error over the whole recording. A model whose healthy-data error
#: already corresponds to a state error that large cannot tell a 10 % capacity fade, a doubled
#: resistance or a 25 K colder cell from its own misfit (the decision needs the baseline's
#: held-out error several times the floor). For comparison, identifications that work reach 3-8 mV
#: per cell on synthetic truths with 5 mV noise and 22-24 mV on the measured Panasonic cell with
#: another chemistry's OCPs (docs/identification.md). Only the excess over the noise counts (white
#: noise no model can fit, :func:`~battery_predictor.diagnosis.decision.excess_mv`).
POOR_EXCESS_MV_PER_CELL = 40.0
# The particle diffusivities (TRANSPORT_COORDINATES) are searched in a second identification that starts from the
# first one's result (identify_reference). On a flat open-circuit voltage (LFP) the end of a working day is shaped by
# solid diffusion: a far-truth Ranger reference day (diffusivities x0.5-2 of the params') was fitted to 71.8 mV
# without them and 9.9 mV with them (docs/findings.md).


@dataclass
class ReferenceFit:
    """Outcome of the baseline fit on the reference data.

    Attributes
    ----------
    values : dict
        Fitted identifiable coordinates (shared ones; see ``initial_ocv_v``).
    socs : list of float
        Initial open-circuit voltage (V per cell) of each reference recording.
    rmse_mV : float
        Root mean square over the recordings of each recording's RMSE (mV, pack).
    initial_rmse_mV : float
        The same at the params' own values (start of the search).
    evaluations : int
        Model evaluations spent.
    skipped : list of str
        Fit parameters of the params not searched (kept at their values).
    seconds : float
        Wall time (s).
    r2_mod : float
        Mean R2_mod (seed paper Eq. 1-3) of the fit.
    rmse_mV_per_recording, r2_mod_per_recording : list of float
        Per reference recording.
    simulator : str
        ``engine`` or the fallback's name.
    series : int
        Cells in series (for per-cell figures).
    extra : list of str
        Optional coordinates searched as well (:data:`TRANSPORT_COORDINATES` when they were kept).
    end_padding : bool
        Whether references ending at their minimum voltage were padded as stopped at their cut-off.
    """

    values: dict[str, float]
    socs: list[float]
    rmse_mV: float
    initial_rmse_mV: float
    evaluations: int
    skipped: list[str]
    seconds: float
    r2_mod: float = float("nan")
    rmse_mV_per_recording: list[float] = field(default_factory=list)
    r2_mod_per_recording: list[float] = field(default_factory=list)
    simulator: str = "engine"
    series: int = 1
    extra: list[str] = field(default_factory=list)
    end_padding: bool = False

    @property
    def rmse_mV_per_cell(self) -> float:
        return self.rmse_mV / max(self.series, 1)

    def to_json(self) -> dict:
        return {"rmse_mV": self.rmse_mV, "initial_rmse_mV": self.initial_rmse_mV, "r2_mod": self.r2_mod,
                "rmse_mV_per_recording": list(self.rmse_mV_per_recording),
                "r2_mod_per_recording": list(self.r2_mod_per_recording),
                "evaluations": self.evaluations, "values": dict(self.values), "initial_soc": list(self.socs),
                "not_fitted": list(self.skipped), "seconds": self.seconds, "simulator": self.simulator,
                "method": "identify", "extra_coordinates": list(self.extra),
                "end_padding": self.end_padding}


def _rms(values: Sequence[float]) -> float:
    vals = [float(v) for v in values if math.isfinite(float(v))]
    return math.sqrt(sum(v * v for v in vals) / len(vals)) if vals else float("nan")


def identify_reference(params: PackParams, references: Sequence[Recording], budget: int = DEFAULT_IDENTIFY_BUDGET,
                       seed: int = 0, progress: Callable[[str], None] | None = None, noise_mv: float = 0.0
                       ) -> tuple[PackParams, ReferenceFit]:
    """Identify ``params`` on the reference recordings (``fit --method identify`` on the SPM engine).

    On the engine, a second identification then also searches the particle diffusivities
    (:data:`TRANSPORT_COORDINATES`, where the params give them as scalars), starting from the first
    one's result with the same budget; it is kept only when it fits the references separably better
    (:func:`separably_better`), the rule by which the decision prefers the simpler of two candidates.
    When a reference ends at its minimum voltage while discharging
    (:func:`~battery_predictor.recording.ends_at_cutoff`), the seed paper's end padding asks the
    model to be empty there; an identification without it runs too, and the padding is dropped when
    that one fits the references separably better (the reference did not stop at its cut-off: an
    LFP working day that ends on the onset of its knee fitted to 207.5 mV padded, 9.3 mV without).

    Parameters
    ----------
    params : PackParams
        The starting model.
    references : sequence of Recording
        Recordings without the effect (whole: rests and recharges are simulated).
    budget : int
        Model evaluations (each simulates every reference once). On params the engine does not
        cover, at most :data:`FALLBACK_BUDGET`.
    seed : int
        TPE seed.
    noise_mv : float
        Voltage noise of the references (mV; :func:`~battery_predictor.diagnosis.scoring.noise_level_v`).

    Returns
    -------
    (PackParams, ReferenceFit)
        The params with the identified values (initial concentrations = the first reference's
        start, as ``fit`` writes them) and the fit's figures.
    """
    import warnings

    from battery_predictor.fitting.identifiable import default_space
    from battery_predictor.fitting.identification import IdentificationProblem, identify
    from battery_predictor.fitting.problem import request_for_recording
    from battery_predictor.simulation.engine import EngineSimulator

    tic = time.perf_counter()
    simulator = EngineSimulator()
    reason = EngineSimulator.unsupported_reason(params, request_for_recording(params, references[0]))
    name = "engine"
    if reason is not None:
        budget = min(budget, FALLBACK_BUDGET)
        name = "fast"
        _log(progress, f"reference fit: {reason}; the fast simulator with {budget} evaluations")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        space = default_space(params, references)
    for w in caught:
        _log(progress, f"warning: {w.message}")
    problem = IdentificationProblem(params=params, recordings=list(references), simulator=simulator, space=space)
    start = {c.name: c.initial for c in space}
    try:
        initial_rmse = _rms(problem.score(start).rmse_mv)
    except BatteryPredictorError:
        initial_rmse = float("nan")
    _log(progress, f"reference fit (identification on the {name} simulator): {len(space)} coordinates, budget "
                   f"{budget} evaluations, initial RMSE {initial_rmse:.1f} mV")

    def show(phase: str, evaluations: int, cost: float) -> None:
        _log(progress, f"reference fit: {phase}: {evaluations} evaluations, 1 - cost = {1.0 - cost:.4f}")

    result = identify(problem, evaluations=max(int(budget), 2), seed=seed, progress=show)
    best = problem.score(result.coordinates)
    evaluations = result.evaluations
    extra: list[str] = []
    if name == "engine":
        fit = _Fit(problem, result, best)
        fit, n_padding = _padding_choice(params, references, simulator, fit, budget, seed, show, noise_mv, progress)
        fit, n_transport, extra = _transport_choice(params, references, simulator, fit, budget, seed, show,
                                                    noise_mv, progress)
        problem, result, best = fit
        space, evaluations = problem.space, evaluations + n_padding + n_transport
    fitted = reachable_soc_window(params.with_values(best.values[0]), progress)
    states = [result.coordinates[c.name] for c in space if c.recording is not None]
    info = ReferenceFit(values={k: float(v) for k, v in result.coordinates.items() if not k.startswith("initial_ocv")},
                        socs=[float(s) for s in states], rmse_mV=_rms(best.rmse_mv), initial_rmse_mV=initial_rmse,
                        evaluations=evaluations, skipped=[], seconds=time.perf_counter() - tic,
                        r2_mod=float(best.r2_mod), rmse_mV_per_recording=[float(x) for x in best.rmse_mv],
                        r2_mod_per_recording=[float(x) for x in best.per_recording], simulator=name,
                        series=params.series, extra=extra,
                        end_padding=problem.cutoff_ends and any(ends_at_cutoff(r) for r in references))
    _log(progress, f"reference fit: RMSE {initial_rmse:.1f} -> {info.rmse_mV:.1f} mV, R2_mod {info.r2_mod:.4f} "
                   f"({info.evaluations} evaluations, {info.seconds:.0f} s)")
    return fitted, info


class _Fit(NamedTuple):
    """One identification of the references: its problem, result and score."""

    problem: IdentificationProblem
    result: IdentificationResult
    best: CandidateScore


def _padding_choice(params: PackParams, references: Sequence[Recording], simulator: PackSimulator, fit: _Fit,
                    budget: int, seed: int, show: Callable[[str, int, float], None], noise_mv: float,
                    progress: Callable[[str], None] | None) -> tuple[_Fit, int]:
    """The end padding kept, or dropped when an identification without it fits separably better.

    The padding assumes a reference that ends at its minimum voltage stopped at its cut-off; the data test
    it. Returns the kept fit and the evaluations spent (0 when no reference ends at its minimum voltage).
    """
    if not any(ends_at_cutoff(r) for r in references):
        return fit, 0
    free = _Fit(*_identify(params, references, simulator, fit.problem.space, budget, seed, show,
                           "without the end padding", cutoff_ends=False))
    padded_mv, free_mv = _rms(fit.best.rmse_mv), _rms(free.best.rmse_mv)
    kept = not separably_better(padded_mv, free_mv, noise_mv)
    _log(progress, f"reference fit without the end padding (the references ending at their minimum voltage "
                   f"taken as not stopped at their cut-off): RMSE {free_mv:.1f} mV (padded {padded_mv:.1f} mV): "
                   f"{'padding kept' if kept else 'separably better: the references did not stop at their cut-off'}")
    return (fit if kept else free), free.result.evaluations


def _transport_choice(params: PackParams, references: Sequence[Recording], simulator: PackSimulator, fit: _Fit,
                      budget: int, seed: int, show: Callable[[str, int, float], None], noise_mv: float,
                      progress: Callable[[str], None] | None) -> tuple[_Fit, int, list[str]]:
    """The particle diffusivities searched as well, kept when that fits separably better.

    Returns the kept fit, the evaluations spent and the coordinates it adds (empty when not kept).
    """
    transport = _transport_fit(params, references, simulator, fit.result.coordinates, budget, seed, show,
                               cutoff_ends=fit.problem.cutoff_ends)
    if transport is None:
        return fit, 0, []
    other = _Fit(*transport)
    basic_mv, t_mv = _rms(fit.best.rmse_mv), _rms(other.best.rmse_mv)
    kept = separably_better(basic_mv, t_mv, noise_mv)
    _log(progress, f"reference fit with the particle diffusivities: RMSE {t_mv:.1f} mV (without {basic_mv:.1f} "
                   f"mV): {'kept' if kept else 'not separably better, not kept'}")
    if kept:
        return other, other.result.evaluations, list(TRANSPORT_COORDINATES)
    return fit, other.result.evaluations, []


def separably_better(basic_rmse_mv: float, other_rmse_mv: float, noise_mv: float) -> bool:
    """Whether a fit with RMSE ``other_rmse_mv`` is separably better than the ``basic`` one (mV).

    The decision's separability rule (:func:`~battery_predictor.diagnosis.decision.near_lowest`): the
    basic fit (fewer searched values, or the seed paper's end padding) is kept unless its error above
    the noise exceeds :data:`SEPARABILITY_FACTOR` times the other's plus :data:`NEAR_NOISE_FRACTION`
    of the noise (a difference the noise cannot explain).
    """
    from battery_predictor.diagnosis.decision import NEAR_NOISE_FRACTION, SEPARABILITY_FACTOR, excess_mv

    if not math.isfinite(other_rmse_mv):
        return False
    if not math.isfinite(basic_rmse_mv):
        return True
    margin = SEPARABILITY_FACTOR * excess_mv(other_rmse_mv, noise_mv) + NEAR_NOISE_FRACTION * noise_mv
    return excess_mv(basic_rmse_mv, noise_mv) > margin


def _transport_fit(params: PackParams, references: Sequence[Recording], simulator: PackSimulator,
                   start: dict[str, float], budget: int, seed: int, show: Callable[[str, int, float], None],
                   cutoff_ends: bool = True
                   ) -> tuple[IdentificationProblem, IdentificationResult, CandidateScore] | None:
    """The identification with :data:`TRANSPORT_COORDINATES` from ``start``: (problem, result, score), or None.

    None when the params give a diffusivity as a function (not a scalar to search) or the fit fails.
    """
    import dataclasses
    import warnings

    from battery_predictor.errors import ParamsError
    from battery_predictor.fitting.identifiable import default_space

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            space = default_space(params, references, extra=TRANSPORT_COORDINATES)
    except ParamsError:
        return None
    space = [dataclasses.replace(c, initial=min(max(float(start.get(c.name, c.initial)), c.low), c.high))
             for c in space]
    try:
        return _identify(params, references, simulator, space, budget, seed, show, "with diffusivities",
                         cutoff_ends=cutoff_ends)
    except BatteryPredictorError:
        return None


def _identify(params: PackParams, references: Sequence[Recording], simulator: PackSimulator, space: list[Coordinate],
              budget: int, seed: int, show: Callable[[str, int, float], None], label: str, *, cutoff_ends: bool
              ) -> tuple[IdentificationProblem, IdentificationResult, CandidateScore]:
    """One more identification of the references over ``space`` (its progress phases prefixed ``label``):
    (problem, result, score of the result)."""
    from battery_predictor.fitting.identification import IdentificationProblem, identify

    problem = IdentificationProblem(params=params, recordings=list(references), simulator=simulator, space=space,
                                    cutoff_ends=cutoff_ends)
    result = identify(problem, evaluations=max(int(budget), 2), seed=seed,
                      progress=lambda phase, n, cost: show(f"{label}, {phase}", n, cost))
    return problem, result, problem.score(result.coordinates)


def reachable_soc_window(params: PackParams, progress: Callable[[str], None] | None = None) -> PackParams:
    """``params`` whose 0 % / 100 % SOC open-circuit voltages the identified cell can reach.

    The diagnosis states each recording's start as an SOC between the params' ``Open-circuit voltage
    at 0% / 100% SOC [V]``. An identification moves the electrode capacities and the lithium
    inventory; on a flat OCP (LFP) the identified cell may no longer reach those voltages. They are
    then moved 1 mV inside the range the identified cell reaches (reported on ``progress``).
    """
    from battery_predictor.diagnosis.engine import Engine
    from battery_predictor.errors import SimulationError

    engine = Engine()
    try:
        engine.stoichiometry_window(params)
        return params
    except SimulationError:
        pass
    pv = cached_parameter_values(params)
    grid, u_n, u_p = engine._ocp_tables(params, pv)
    n_n, n_p, li = engine.loadings(pv, {})
    lo = max(grid[0], (li - n_p * grid[-1]) / n_n)
    hi = min(grid[-1], (li - n_p * grid[0]) / n_n)
    if not lo < hi:
        raise SimulationError("the identified lithium inventory does not fit into the electrodes")
    x = np.linspace(lo, hi, 4001)
    ocv = np.interp((li - n_n * x) / n_p, grid, u_p) - np.interp(x, grid, u_n)
    v_lo, v_hi = float(np.min(ocv)) + 1e-3, float(np.max(ocv)) - 1e-3
    key0, key100 = "Open-circuit voltage at 0% SOC [V]", "Open-circuit voltage at 100% SOC [V]"
    ocv0 = min(max(float(pv[key0]), v_lo), v_hi)
    ocv100 = min(max(float(pv[key100]), v_lo), v_hi)
    _log(progress, f"reference fit: the identified cell reaches {v_lo:.3f}-{v_hi:.3f} V open-circuit; its 0/100 % "
                   f"SOC voltages are taken as {ocv0:.3f} / {ocv100:.3f} V (params: {float(pv[key0]):.3f} / "
                   f"{float(pv[key100]):.3f} V)")
    return params.with_values({key0: ocv0, key100: ocv100})


def excess_per_cell_mv(ref: ReferenceFit, noise_mv: float) -> float:
    """The reference fit's error above the voltage noise, per cell in series (mV)."""
    return math.sqrt(max(ref.rmse_mV ** 2 - noise_mv ** 2, 0.0)) / max(ref.series, 1)


def reference_verdict(ref: ReferenceFit, noise_mv: float) -> str | None:
    """None when the reference fit can serve as the baseline, else why not and what to do (one paragraph).

    Poor = its error above the noise exceeds :data:`POOR_EXCESS_MV_PER_CELL` per cell in series, or
    it did not produce a finite error at all.
    """
    excess = excess_per_cell_mv(ref, noise_mv)
    if math.isfinite(excess) and excess <= POOR_EXCESS_MV_PER_CELL:
        return None
    per_rec = ", ".join(f"{r:.0f}" for r in ref.rmse_mV_per_recording)
    return (f"Not judged: the reference fit is too poor to judge candidates against. It leaves an RMSE of "
            f"{ref.rmse_mV:.1f} mV (per recording: {per_rec} mV; {ref.rmse_mV_per_cell:.1f} mV per cell in series, "
            f"{excess:.1f} mV per cell above the {noise_mv:.1f} mV voltage noise) and R2_mod {ref.r2_mod:.4f} on the "
            f"healthy reference data, above the {POOR_EXCESS_MV_PER_CELL:.0f} mV per cell that a usable reference "
            f"leaves (about a 6-7 % SOC error on an NMC/NCA open-circuit voltage): any effect of realistic size would "
            f"drown in the model's own error, so no cause - not even 'none' - is named. What to do: raise "
            f"--reference-budget (now {ref.evaluations} evaluations), check that the reference recordings belong to "
            f"this pack and --params describe its chemistry (OCPs, series/parallel count), give references that "
            f"cover the observed operating range (complete discharges, same load kind), or fit the params first "
            f"with 'battery-predictor fit --method identify' and run diagnose on the fitted params without "
            f"--reference.")


def _log(progress: Callable[[str], None] | None, msg: str) -> None:
    if progress is not None:
        progress(msg)


__all__ = ["DEFAULT_IDENTIFY_BUDGET", "POOR_EXCESS_MV_PER_CELL", "ReferenceFit", "TRANSPORT_COORDINATES",
           "excess_per_cell_mv", "identify_reference", "reference_verdict", "separably_better"]


def reference_anchor_k(temperature_traces_k: Sequence[npt.ArrayLike | None], currents_a: Sequence[npt.ArrayLike]
                       ) -> float:
    """The anchor temperature of the extension ``temperature`` from the reference recordings (K).

    The identified model's accessible capacity is set where each reference discharge ended, at the
    temperature the cell had then (a 2C reference self-heats by 30 K before its knee): the anchor is
    the mean, over the reference recordings, of the measured temperature at each one's last
    discharging sample (current above 1 % of its largest discharge current).

    Parameters
    ----------
    temperature_traces_k : sequence of numpy.ndarray
        Each reference recording's measured temperature (K).
    currents_a : sequence of numpy.ndarray
        Each reference recording's current (A, discharge positive).

    Returns
    -------
    float
        The anchor temperature in K.
    """
    ends = []
    for temp, current in zip(temperature_traces_k, currents_a):
        cur = np.asarray(current, dtype=float)
        dis = np.nonzero(cur > 0.01 * max(float(np.max(cur)), 0.0))[0]
        ends.append(float(np.asarray(temp, dtype=float)[dis[-1] if dis.size else -1]))
    return float(np.mean(ends))
