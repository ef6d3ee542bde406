"""How sure the predictor is: P10 / P50 / P90 remaining time and the probability a route stays above its threshold.

A prediction is uncertain for four reasons, each propagated through the pack model:

- **the load ahead**: the present cycle's mean load is a sample of a usage that varies from
  block to block (:func:`future_load_sigma`); the runtime is simulated again at the demand raised
  and lowered by the 80 % band of the future mean (:func:`load_scenarios`);
- **the state**: the calibrated SOC reproduces the measured voltage only as well as the model
  fits (the fit's RMSE, or the calibration's own residual when larger); that voltage error
  divided by the pack's OCV slope is the SOC's spread, and the charge it stands for shifts the
  time to the cut-off;
- **the parameters**: what the fit did not determine. The capacity's confidence interval
  (identifiability output of the fit), and the temperature dependence, which a fit at one
  temperature never determines: the Arrhenius activation energies carry a relative prior spread
  (:data:`ACTIVATION_ENERGY_REL_SIGMA`), run as an effective temperature
  (:func:`arrhenius_equivalent_temperature_k`);
- **the model's structure**: what remains, calibrated on the fit recordings' own checkpoints so
  that P10..P90 holds 80 % of them (:func:`calibrated_model_sigma`, ``evaluate-runtime
  --calibrate-uncertainty``), stored in the params' ``provenance.uncertainty``.

The parts are combined as independent deviations of the log remaining time (of the voltage for
routes) at the band's quantile: the lower and upper deviations separately, because the load and
temperature scenarios are not symmetric. An undecided load kind is not a spread but a second
possible model: its deviation is added to the others' (the band of a mixture reaches the other
model's band), :data:`MIXTURE_SOURCES`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.prediction.route import RouteDecision, evaluate_route, route_segments
from battery_predictor.prediction.runtime import demand_run, load_horizon_s, run_end_s
from battery_predictor.profiles.ranger import DEFAULT_POINT_DURATION_S, std_current_a

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel, RunStart
    from battery_predictor.prediction.runtime import RuntimePrediction
    from battery_predictor.profiles.ranger import RangerCurrents, RouteSection

#: Standard normal quantile of 0.9: P10 and P90 lie this many sigmas from P50.
Z_P90 = NormalDist().inv_cdf(0.9)
#: Relative spread of the activation energies (diffusion, kinetics, resistance) a fit at one
#: temperature leaves undetermined (literature values for one material differ by this much).
ACTIVATION_ENERGY_REL_SIGMA = 0.3
#: Without a calibration in the params: the structural error of a remaining time (log) and the
#: model's voltage error per series cell (V). Measured on the Panasonic fit recordings
#: (docs/uncertainty): 0.09 and 36-47 mV RMSE; taken a little wider for uncalibrated params.
DEFAULT_RUNTIME_LOG_SIGMA = 0.25
DEFAULT_CELL_VOLTAGE_SIGMA_V = 0.02
#: Relative capacity spread when the params carry no identifiability output (new cells of one lot).
DEFAULT_CAPACITY_REL_SIGMA = 0.02
#: Usage varies from block to block of this length (s); a future mean over T s averages T / block blocks.
LOAD_BLOCK_S = 300.0
#: Fewer complete blocks than this: the spread of the windows is taken instead (wider).
MIN_LOAD_BLOCKS = 3
#: Sources that are alternative models, not spreads: added to the root-sum-square of the others.
MIXTURE_SOURCES = ("load_kind",)


@dataclass(frozen=True)
class UncertaintyModel:
    """The spreads a pack's params carry beyond what is simulated.

    Attributes
    ----------
    runtime_log_sigma : float
        Structural error of a remaining time, standard deviation of its logarithm.
    voltage_sigma_v : float
        The model's pack-voltage error, V (the fit's RMSE).
    capacity_rel_sigma : float
        Relative standard deviation of the pack capacity (the fit's confidence interval).
    activation_energy_rel_sigma : float
        Relative standard deviation of the Arrhenius activation energies.
    reference_temperature_k : float
        Temperature the params were fitted at, K (no temperature spread there).
    source : str
        Where the figures come from, for reasons and logs.
    """

    runtime_log_sigma: float
    voltage_sigma_v: float
    capacity_rel_sigma: float
    activation_energy_rel_sigma: float
    reference_temperature_k: float
    source: str


def _finite_positive(value: Any) -> float | None:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return None
    return out if math.isfinite(out) and out >= 0 else None


def _capacity_rel_sigma(identifiability: Any) -> float | None:
    """Largest relative sigma (95 % interval / 3.92) of the fitted electrode capacities, or None."""
    if not isinstance(identifiability, Mapping):
        return None
    sigmas = []
    for entry in identifiability.get("parameters") or []:
        if not isinstance(entry, Mapping) or not str(entry.get("name", "")).endswith("capacity_ah"):
            continue
        ci = entry.get("ci95") or []
        value = _finite_positive(entry.get("value"))
        if len(ci) == 2 and value and all(math.isfinite(float(c)) for c in ci):
            sigmas.append((float(ci[1]) - float(ci[0])) / 3.92 / value)
    return max(sigmas) if sigmas else None


def uncertainty_model(provenance: Mapping[str, Any], series: int, reference_temperature_k: float) -> UncertaintyModel:
    """The :class:`UncertaintyModel` of a params file's ``provenance`` (defaults where it says nothing).

    Parameters
    ----------
    provenance : mapping
        ``PackParams.provenance``: ``uncertainty.runtime_log_sigma`` (written by ``evaluate-runtime
        --calibrate-uncertainty``), ``rmse_mv_per_file`` and ``identifiability`` (written by ``fit``).
    series : int
        Cells in series (the default voltage error is per cell).
    reference_temperature_k : float
        Temperature of the fit data, K.
    """
    sources = []
    stored = provenance.get("uncertainty")
    calibrated: Mapping[str, Any] = stored if isinstance(stored, Mapping) else {}
    runtime_sigma = _finite_positive(calibrated.get("runtime_log_sigma"))
    if runtime_sigma is None:
        runtime_sigma = DEFAULT_RUNTIME_LOG_SIGMA
        sources.append(f"runtime spread uncalibrated ({DEFAULT_RUNTIME_LOG_SIGMA:.2f})")
    else:
        sources.append(f"runtime spread {runtime_sigma:.3f} calibrated on {calibrated.get('checkpoints', '?')} "
                       "checkpoints")
    rmse = [v for v in (_finite_positive(x) for x in provenance.get("rmse_mv_per_file") or []) if v is not None]
    if rmse:
        voltage_sigma = math.sqrt(float(np.mean(np.square(rmse)))) / 1000.0
    else:
        voltage_sigma = DEFAULT_CELL_VOLTAGE_SIGMA_V * series
        sources.append(f"voltage error assumed {DEFAULT_CELL_VOLTAGE_SIGMA_V * 1000:.0f} mV per cell (no fit RMSE)")
    capacity = _capacity_rel_sigma(provenance.get("identifiability"))
    if capacity is None:
        capacity = DEFAULT_CAPACITY_REL_SIGMA
    return UncertaintyModel(runtime_sigma, voltage_sigma, capacity, ACTIVATION_ENERGY_REL_SIGMA,
                            reference_temperature_k, "; ".join(sources))


def arrhenius_equivalent_temperature_k(temperature_k: float, reference_temperature_k: float, factor: float) -> float:
    """Temperature (K) at which Arrhenius terms with activation energies scaled by ``factor`` equal those at ``temperature_k``.

    ``exp(f E/R (1/T_ref - 1/T)) = exp(E/R (1/T_ref - 1/T'))`` gives
    ``1/T' = 1/T_ref - f (1/T_ref - 1/T)``: the model runs at ``T'`` instead of refitting ``E``.
    """
    inverse = 1.0 / reference_temperature_k - factor * (1.0 / reference_temperature_k - 1.0 / temperature_k)
    return 1.0 / inverse


def future_load_sigma(stamps_s: Sequence[float] | np.ndarray, demand: Sequence[float] | np.ndarray,
                      horizon_s: float) -> float:
    """Relative standard deviation of the mean demand over the next ``horizon_s`` s.

    The present cycle's windows (stamps in s, demand in A or W) are pooled into
    :data:`LOAD_BLOCK_S` blocks. A future mean over ``T`` s averages ``T / block`` blocks of
    the block spread ``s_b``; below one block it moves towards the window spread ``s_w``. The
    present mean itself is known to ``s_b / sqrt(n)`` from ``n`` past blocks. With fewer than
    :data:`MIN_LOAD_BLOCKS` complete blocks, ``s_b`` is estimated from the windows: a block
    averages ``block / tau`` independent stretches of the windows' integrated autocorrelation
    time ``tau`` (:func:`correlation_time_s`). Returns 0 for a steady load and NaN without data.
    """
    t = np.asarray(stamps_s, dtype=float)
    d = np.asarray(demand, dtype=float)
    ok = np.isfinite(t) & np.isfinite(d)
    t, d = t[ok], d[ok]
    if t.size < 2:
        return math.nan
    mean = float(np.mean(d))
    if not mean > 0:
        return math.nan
    s_w = float(np.std(d, ddof=1)) / mean
    index = np.floor((t - t[0]) / LOAD_BLOCK_S).astype(int)
    complete = index < index[-1]  # the last block is still filling
    n = int(index[-1])
    if n >= MIN_LOAD_BLOCKS:
        counts = np.bincount(index[complete])
        means = np.bincount(index[complete], weights=d[complete])[counts > 0] / counts[counts > 0]
        s_b = float(np.std(means, ddof=1)) / mean if means.size > 1 else s_w
    else:
        tau_s = correlation_time_s(t, d)
        s_b, n = s_w * math.sqrt(min(tau_s / LOAD_BLOCK_S, 1.0)), max(n, 1)
    horizon_s = max(float(horizon_s), 1.0)
    if horizon_s >= LOAD_BLOCK_S:
        future_var = s_b ** 2 * LOAD_BLOCK_S / horizon_s
    else:
        share = horizon_s / LOAD_BLOCK_S
        future_var = s_b ** 2 + max(s_w ** 2 - s_b ** 2, 0.0) * (1.0 - share)
    return math.sqrt(future_var + s_b ** 2 / n)


def correlation_time_s(stamps_s: np.ndarray, values: np.ndarray) -> float:
    """Integrated autocorrelation time (s) of a regularly sampled series: ``dt (1 + 2 sum rho_k)``.

    The autocorrelations ``rho_k`` are summed up to the first lag where they are no longer
    positive (the initial positive sequence); the sample step ``dt`` is the median spacing.
    Returns the full span for a series that never decorrelates and ``dt`` for a constant one.
    """
    dt = float(np.median(np.diff(stamps_s))) if stamps_s.size > 1 else 1.0
    x = values - float(np.mean(values))
    var = float(np.dot(x, x))
    if var <= 0 or x.size < 3:
        return dt
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n] / var
    nonpositive = np.nonzero(acf[1:] <= 0)[0]
    last = int(nonpositive[0]) if nonpositive.size else n - 1
    return dt * (1.0 + 2.0 * float(np.sum(acf[1:last + 1])))


@dataclass(frozen=True)
class Spread:
    """Deviations at the band's quantile (log remaining time, or V for routes), lower and upper.

    Attributes
    ----------
    lower, upper : dict
        ``{source: deviation}`` (>= 0) toward shorter / longer runtimes (lower / higher voltages).
    """

    lower: dict[str, float]
    upper: dict[str, float]

    def total(self) -> tuple[float, float]:
        """Lower and upper deviation of the band: root-sum-square of the spreads plus the alternative models'."""
        return _combined(self.lower), _combined(self.upper)

    def with_model_sigma(self, sigma_log: float) -> Spread:
        """The same spread with the structural part at ``sigma_log`` (log, one standard deviation)."""
        band = Z_P90 * sigma_log
        return Spread({**self.lower, "model": band}, {**self.upper, "model": band})


def _combined(parts: dict[str, float]) -> float:
    spread = math.sqrt(sum(v ** 2 for k, v in parts.items() if k not in MIXTURE_SOURCES))
    return spread + sum(v for k, v in parts.items() if k in MIXTURE_SOURCES)


def interval(p50: float, lower_log: float, upper_log: float) -> tuple[float, float]:
    """(P10, P90) of a positive quantity whose log deviates by ``lower_log`` / ``upper_log`` at the band."""
    return p50 * math.exp(-lower_log), p50 * math.exp(upper_log)


def charge_deviation_log(delta_ah: float, charge_to_cutoff_ah: float) -> tuple[float, float]:
    """Log deviations (shorter, longer) of a runtime when ``delta_ah`` more or less charge is available.

    The time to the cut-off scales with the charge available to it (``charge_to_cutoff_ah`` at P50).
    """
    if not (charge_to_cutoff_ah > 0 and math.isfinite(delta_ah)):
        return 0.0, 0.0
    share = abs(delta_ah) / charge_to_cutoff_ah
    return -math.log(max(1.0 - share, 0.05)), math.log1p(share)


def state_deviation_log(delta_soc: float, soc: float, top_soc: float, capacity_ah: float,
                        charge_to_cutoff_ah: float) -> tuple[float, float]:
    """Log deviations (shorter, longer) of a runtime from a state known to +-``delta_soc``.

    The longer side holds at most the charge up to the top of the model's SOC range (``top_soc``): more
    cannot be in the cell, however flat its OCV. On LiFePO4's plateau a 50 mV residual over a slope of a
    few 0.1 V per unit SOC gave a P90 of 219 min in a 52 min discharge (K2 26650, 40 degC,
    docs/runtime_real_data/other_cells.md).
    """
    lower, _ = charge_deviation_log(delta_soc * capacity_ah, charge_to_cutoff_ah)
    headroom = max(top_soc - soc, 0.0) if math.isfinite(top_soc) else delta_soc
    _, upper = charge_deviation_log(min(delta_soc, headroom) * capacity_ah, charge_to_cutoff_ah)
    return lower, upper


def calibrated_model_sigma(p50_s: Sequence[float], true_s: Sequence[float], spreads: Sequence[Spread],
                           coverage: float = 0.8) -> float:
    """Smallest structural sigma (log) with which P10..P90 holds ``coverage`` of the checkpoints.

    Each checkpoint's P50 (s), truth (s) and :class:`Spread` (its structural part is replaced).
    Returns 0 when the other parts already cover enough, NaN without usable checkpoints.
    """
    rows = [(math.log(t / p), s) for p, t, s in zip(p50_s, true_s, spreads)
            if p > 0 and t > 0 and math.isfinite(p) and math.isfinite(t)]
    if not rows:
        return math.nan

    def covered(sigma: float) -> float:
        inside = 0
        for err, spread in rows:
            lo, hi = spread.with_model_sigma(sigma).total()
            inside += -lo <= err <= hi
        return inside / len(rows)

    if covered(0.0) >= coverage:
        return 0.0
    a, b = 0.0, 0.05
    while covered(b) < coverage and b < 10.0:
        a, b = b, 2.0 * b
    for _ in range(40):
        mid = 0.5 * (a + b)
        a, b = (a, mid) if covered(mid) >= coverage else (mid, b)
    return b


#: SOC grid (and half step) of the OCV slope; relaxed OCVs on it are cached per runner and kelvin.
OCV_GRID = 0.01
OCV_HALF_STEP = 0.02


@functools.lru_cache(maxsize=512)
def _relaxed_pack_voltage_v(runner: PackModel, soc: float, temperature_k: float) -> float:
    """Pack voltage (V) of a relaxed state at ``soc`` after 1 s at no current (its OCV); NaN when the model fails."""
    try:
        return float(runner.run(soc, [(1.0, 0.0)], temperature_k).pack_voltage_v[-1])
    except BatteryPredictorError:
        return math.nan


def pack_ocv_slope_v(runner: PackModel, soc: float, temperature_k: float) -> float:
    """Pack open-circuit voltage per unit SOC at ``soc`` (V), from relaxed model states (NaN when unknown).

    A central difference over :data:`OCV_HALF_STEP` around the nearest :data:`OCV_GRID` point
    (one-sided at the ends of the runner's SOC range), so that repeated answers reuse the OCVs.
    """
    lo, hi = runner.soc_bounds
    centre = round(soc / OCV_GRID) * OCV_GRID
    a = round(max(centre - OCV_HALF_STEP, lo), 6)
    b = round(min(centre + OCV_HALF_STEP, hi), 6)
    if not b > a:
        return math.nan
    kelvin = float(round(temperature_k))
    slope = (_relaxed_pack_voltage_v(runner, b, kelvin) - _relaxed_pack_voltage_v(runner, a, kelvin)) / (b - a)
    return slope if math.isfinite(slope) and slope > 0 else math.nan


#: SOC step of :func:`ocv_band_soc_span`.
SPAN_GRID = 0.02


def ocv_band_soc_span(runner: PackModel, soc: float, band_v: float, temperature_k: float) -> float:
    """How much SOC (fraction of the capacity) has a pack OCV within ``band_v`` (V) of the OCV at ``soc``.

    How little a voltage known to ``band_v`` says about the state: 0.1-0.2 on a sloped NMC curve with 50 mV per
    cell, 0.5-0.8 on LiFePO4's plateaus (the OCVs on a :data:`SPAN_GRID` grid, cached as
    :func:`pack_ocv_slope_v`'s). NaN when the model gives no OCV at ``soc``.
    """
    lo, hi = runner.soc_bounds
    kelvin = float(round(temperature_k))
    grid = np.round(np.arange(lo, hi + 0.5 * SPAN_GRID, SPAN_GRID), 6)
    ocv = np.array([_relaxed_pack_voltage_v(runner, float(g), kelvin) for g in grid])
    here = float(ocv[np.argmin(np.abs(grid - soc))])
    if not math.isfinite(here):
        return math.nan
    return SPAN_GRID * float(np.count_nonzero(np.abs(ocv - here) <= band_v))


@dataclass(frozen=True)
class LoadAhead:
    """The average load a runtime prediction holds, as :func:`~.runtime.demand_run` takes it.

    Attributes
    ----------
    current_a, power_w : float
        Mean current (A) and power (W) of the present cycle (``power_w`` unused for ``exponent`` 0).
    exponent : float
        ``k`` of the constant demand ``I V^k``.
    sigma : float
        Relative standard deviation of its mean over the remaining time (:func:`future_load_sigma`).
    undecided_exponent : float or None
        When the cycle has not yet shown whether its load is a current or a power, the other
        kind's exponent: its runtime is a scenario of the interval. None when decided.
    """

    current_a: float
    power_w: float
    exponent: float
    sigma: float
    undecided_exponent: float | None = None


def _end_s(runner: PackModel, start: RunStart, load: LoadAhead, factor: float, temperature_k: float, first_voltage_v: float,
           cutoff_v: float, soc: float, exponent: float | None = None) -> float | None:
    """Average-load end time (s) with the demand scaled by ``factor`` (None when it fails or is beyond reach)."""
    current = load.current_a * factor
    horizon_s = load_horizon_s(runner, soc, current)
    k = load.exponent if exponent is None else exponent
    try:
        run, _ = demand_run(runner, start, current, load.power_w * factor, k, horizon_s, temperature_k,
                            first_voltage_v, cutoff_v)
    except BatteryPredictorError:
        return None
    end = run_end_s(run, cutoff_v)
    return horizon_s if end is None else end


def _log_ratios(base_s: float, shorter_s: float | None, longer_s: float | None) -> tuple[float, float]:
    lower = math.log(base_s / shorter_s) if shorter_s and shorter_s > 0 else 0.0
    upper = math.log(longer_s / base_s) if longer_s and longer_s > 0 else 0.0
    return max(lower, 0.0), max(upper, 0.0)


def runtime_spread(runner: PackModel, start: RunStart, soc: float, prediction: RuntimePrediction, load: LoadAhead, model: UncertaintyModel,
                   state_voltage_sigma_v: float, first_voltage_v: float) -> Spread | None:
    """The P10..P90 deviations of a remaining-time prediction (log), by source; None without an end.

    Parameters
    ----------
    runner : PackModel
        The pack model.
    start : float or RunState
        The calibrated start the prediction ran from; ``soc`` its SOC.
    prediction : RuntimePrediction
        The P50 answer (its average-load end time and the charge drawn until then).
    load : LoadAhead
        The load it held and its spread.
    model : UncertaintyModel
        Spreads of the params.
    state_voltage_sigma_v : float
        Pack-voltage error of the calibrated state, V.
    first_voltage_v : float
        Latest measured pack voltage, V.
    """
    base_s, charge_ah = prediction.average_end_s, prediction.charge_to_end_ah
    if not (math.isfinite(base_s) and base_s > 0 and charge_ah > 0):
        return None
    temp, cutoff = prediction.assumed_temperature_k, prediction.cutoff_voltage_v
    lower: dict[str, float] = {}
    upper: dict[str, float] = {}

    def end(factor: float = 1.0, temperature_k: float = temp, exponent: float | None = None) -> float | None:
        return _end_s(runner, start, load, factor, temperature_k, first_voltage_v, cutoff, soc, exponent)

    if load.sigma > 0:
        factor = math.exp(Z_P90 * load.sigma)
        lower["load"], upper["load"] = _log_ratios(base_s, end(factor), end(1.0 / factor))
    if load.undecided_exponent is not None and load.power_w > 0:
        other = end(exponent=load.undecided_exponent)
        lower["load_kind"], upper["load_kind"] = _log_ratios(base_s, other if other and other < base_s else None,
                                                             other if other and other > base_s else None)
    slope = pack_ocv_slope_v(runner, soc, temp)
    delta_soc = Z_P90 * state_voltage_sigma_v / slope if math.isfinite(slope) else 0.5
    lower["state"], upper["state"] = state_deviation_log(delta_soc, soc, runner.soc_bounds[1], runner.capacity_ah,
                                                         charge_ah)
    cap_lo, cap_hi = charge_deviation_log(Z_P90 * model.capacity_rel_sigma * charge_ah, charge_ah)
    temp_lo = temp_hi = 0.0
    if abs(temp - model.reference_temperature_k) > 0.5:
        ends = [end(temperature_k=arrhenius_equivalent_temperature_k(
            temp, model.reference_temperature_k, 1.0 + sign * Z_P90 * model.activation_energy_rel_sigma))
            for sign in (1.0, -1.0)]
        finite = [e for e in ends if e is not None]
        if finite:
            temp_lo, temp_hi = _log_ratios(base_s, min(finite), max(finite))
    lower["parameters"], upper["parameters"] = math.hypot(cap_lo, temp_lo), math.hypot(cap_hi, temp_hi)
    lower["model"] = upper["model"] = Z_P90 * model.runtime_log_sigma
    return Spread(lower, upper)


def route_charge_sigma_ah(sections: Sequence[RouteSection], currents: RangerCurrents | None = None,
                          point_duration_s: float = DEFAULT_POINT_DURATION_S) -> float:
    """Standard deviation (Ah) of the charge a route draws: each section's mean current is a sample.

    The measured currents of a (payload, slope) set scatter by their standard deviation from one
    curve point (``point_duration_s``) to the next, independently (as the paper's route profiles
    draw them); a section of ``n`` points has a mean current known to ``std / sqrt(n)``.
    """
    var = 0.0
    for sec in sections:
        if sec.length_m > 0 and sec.travel_s > 0:
            n = max(1, math.ceil(sec.travel_s / point_duration_s))
            sigma_a = std_current_a(sec.payload_kg, sec.slope, currents) / math.sqrt(n)
            var += (sec.travel_s / 3600.0 * sigma_a) ** 2
    return math.sqrt(var)


@dataclass(frozen=True)
class RouteSpread:
    """The standard deviation of a route's end voltage and its parts (V).

    Attributes
    ----------
    sigma_v : float
        Total (root-sum-square of ``parts``), V.
    parts : dict
        ``{"model", "state", "load", "parameters"}`` -> V.
    """

    sigma_v: float
    parts: dict[str, float]

    def probability_above(self, margin_v: float) -> float:
        """Probability that the end voltage is at or above the threshold ``margin_v`` below P50."""
        if not math.isfinite(margin_v):
            return math.nan
        if self.sigma_v <= 0:
            return 1.0 if margin_v >= 0 else 0.0
        return NormalDist().cdf(margin_v / self.sigma_v)

    def voltage_at_risk_v(self, p50_v: float, risk: float) -> float:
        """The end voltage (V) the pack stays above with probability ``1 - risk``."""
        return p50_v + NormalDist().inv_cdf(risk) * self.sigma_v


def route_spread(runner: PackModel, start_soc: float, end_soc: float, route_charge_ah: float, charge_sigma_ah: float,
                 temperature_k: float, model: UncertaintyModel, state_voltage_sigma_v: float,
                 end_voltage_at: Callable[[float], float]) -> RouteSpread:
    """Standard deviation (V) of a route's end voltage at the standstill current.

    Parameters
    ----------
    runner : PackModel
        The pack model.
    start_soc, end_soc : float
        SOC at the start and (simulated) at the end of the route.
    route_charge_ah, charge_sigma_ah : float
        Charge the route draws and its standard deviation, Ah.
    temperature_k : float
        Temperature assumed, K.
    model : UncertaintyModel
        Spreads of the params.
    state_voltage_sigma_v : float
        Pack-voltage error of the calibrated state, V.
    end_voltage_at : callable
        ``end_voltage_at(temperature_k) -> V``: the route's end voltage simulated at another
        temperature (the activation-energy scenarios), NaN when it fails.
    """
    slope_now = pack_ocv_slope_v(runner, start_soc, temperature_k)
    slope_end = pack_ocv_slope_v(runner, end_soc, temperature_k)
    per_soc = slope_end / runner.capacity_ah if math.isfinite(slope_end) else math.nan
    parts = {"model": model.voltage_sigma_v}
    ratio = slope_end / slope_now if math.isfinite(slope_now) and math.isfinite(slope_end) else 3.0
    parts["state"] = state_voltage_sigma_v * ratio
    parts["load"] = per_soc * charge_sigma_ah if math.isfinite(per_soc) else model.voltage_sigma_v
    capacity_v = per_soc * route_charge_ah * model.capacity_rel_sigma if math.isfinite(per_soc) else 0.0
    temp_v = 0.0
    if abs(temperature_k - model.reference_temperature_k) > 0.5:
        ends = [end_voltage_at(arrhenius_equivalent_temperature_k(
            temperature_k, model.reference_temperature_k, 1.0 + sign * model.activation_energy_rel_sigma))
            for sign in (1.0, -1.0)]
        temp_v = abs(ends[0] - ends[1]) / 2.0 if all(math.isfinite(e) for e in ends) else model.voltage_sigma_v
    parts["parameters"] = math.hypot(capacity_v, temp_v)
    return RouteSpread(math.sqrt(sum(v ** 2 for v in parts.values())), parts)


def evaluate_route_at_risk(runner: PackModel, start: RunStart, sections: Sequence[RouteSection], temperature_k: float,
                           *, threshold_v: float, standstill_current_a: float, risk: float, model: UncertaintyModel,
                           state_voltage_sigma_v: float, currents: RangerCurrents | None = None) -> RouteDecision:
    """:func:`~.route.evaluate_route`, accepted only when the pack ends above the threshold with probability >= ``1 - risk``.

    ``risk`` 0.5 decides on the P50 voltage alone (the paper's rule); the default 0.1 accepts when
    the P10 voltage after the route is at or above the threshold. Never raises for a bad route.
    """
    try:  # once for the three runs (an invalid route: evaluate_route rejects it with the reason)
        segments: list[tuple[float, float]] | None = route_segments(sections, standstill_current_a, currents)
    except BatteryPredictorError:
        segments = None
    decision = evaluate_route(runner, start, sections, temperature_k, threshold_v=threshold_v,
                              standstill_current_a=standstill_current_a, currents=currents, segments=segments)
    if not math.isfinite(decision.predicted_voltage_v):
        return decision

    def end_voltage_at(temp_k: float) -> float:
        return evaluate_route(runner, start, sections, temp_k, threshold_v=threshold_v,
                              standstill_current_a=standstill_current_a, currents=currents,
                              segments=segments).predicted_voltage_v

    soc = decision.state_of_charge
    end_soc = decision.end_soc(runner.capacity_ah)
    spread = route_spread(runner, soc, end_soc, decision.route_charge_ah, route_charge_sigma_ah(sections, currents),
                          temperature_k, model, state_voltage_sigma_v, end_voltage_at)
    probability = spread.probability_above(decision.margin_v)
    at_risk_v = spread.voltage_at_risk_v(decision.predicted_voltage_v, risk)
    accepted = decision.accepted and at_risk_v >= threshold_v
    verdict = "accepted" if accepted else "rejected"
    parts = ", ".join(f"{k} {v:.2f}" for k, v in spread.parts.items())
    detail = decision.reason.split(": ", 1)[-1]
    reason = (f"{verdict}: {detail}; probability above the threshold {probability:.3f}, "
              f"P{100 * risk:.0f} voltage {at_risk_v:.2f} V (accepted risk {risk:.2f}; sigma {spread.sigma_v:.2f} V: "
              f"{parts})")
    return RouteDecision(accepted, decision.predicted_voltage_v, threshold_v, decision.margin_v,
                         decision.route_duration_s, decision.route_charge_ah, soc, reason, probability, at_risk_v, risk)
