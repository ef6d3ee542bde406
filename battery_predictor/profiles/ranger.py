"""Route load profiles of the AgileX Ranger Mini luggage robot (seed paper 5.2.1-5.2.2).

* :class:`RangerCurrents` holds one current sample set (and Gaussian KDE) per
  payload level (0/20/40/60/80 kg) and slope (flat/uphill/downhill), 15 in
  all, read from ``params/ranger_currents.yaml``.
* A :class:`Route` is a sequence of :class:`RouteSection` (one slope and one
  payload each). :func:`route_from_station` builds the job route
  charger -> pickup (unloaded) -> dropoff (loaded) -> charger (unloaded) on
  the station graph; :func:`longest_route` is the paper's 5-step example.
* :func:`route_profile` turns a route into curve points of at most ~19 s.

Curve-point splitting rule
--------------------------
Each section's travel time is split into ``ceil(travel_s / 19 s)`` points of
equal duration (so every point lasts *at most* 19 s, "approximately 19 s"),
and each standstill is one curve point of its own. Applied per section
(one slope per section) this gives the paper's 97 points for the longest
route: 1 + ceil(380/19) + ceil(690/19) + ceil(150/19) + ceil(150/19)
+ ceil(410/19) + 1 = 1 + 20 + 37 + 8 + 8 + 22 + 1 = 97. Rounding to the
nearest integer instead would give 96 (690/19 = 36.3 -> 36).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from battery_predictor.config import (
    as_float,
    as_float_list,
    check_unknown,
    default_params_file,
    read_yaml_mapping,
    require,
)
from battery_predictor.errors import ParamsError, ProfileError
from battery_predictor.profiles.kde import BoundedKde
from battery_predictor.profiles.load_profile import LoadProfile, constant_current_profile
from battery_predictor.profiles.station import FLAT, SLOPES, Station, check_slope

__all__ = [
    "DEFAULT_POINT_DURATION_S",
    "MAX_PAYLOAD_KG",
    "STANDSTILL_LABEL",
    "RangerCurrents",
    "Route",
    "RouteSection",
    "check_payload_kg",
    "constant_current_profile",
    "curve_points_for",
    "default_currents_path",
    "load_ranger_currents",
    "longest_route",
    "mean_current_a",
    "route_from_station",
    "route_profile",
    "stepwise_profile",
]

#: Default params file shipped with the package.
DEFAULT_CURRENTS_FILE = "ranger_currents.yaml"
#: Payloads above this are rejected as absurd (the robot is rated far below).
MAX_PAYLOAD_KG = 200.0
#: Target curve-point duration of section 5.2.2, s.
DEFAULT_POINT_DURATION_S = 19.0
#: Label of standstill curve points.
STANDSTILL_LABEL = "standstill"
#: Paper values used when no currents file is given (section 5.2).
DEFAULT_SPEED_M_S = 0.50
DEFAULT_STANDSTILL_S = 60.0


def check_payload_kg(payload_kg: float) -> float:
    """Validate a payload in kg: finite, >= 0 and <= :data:`MAX_PAYLOAD_KG`.

    Raises
    ------
    ProfileError
        For NaN, infinite, negative or absurd (> 200 kg) payloads.
    """
    try:
        value = float(payload_kg)
    except (TypeError, ValueError):
        raise ProfileError(f"payload_kg is {payload_kg!r} (must be a number)") from None
    if not math.isfinite(value) or value < 0.0 or value > MAX_PAYLOAD_KG:
        raise ProfileError(f"payload_kg is {payload_kg!r} (must be between 0 and {MAX_PAYLOAD_KG:g} kg)")
    return value


class RangerCurrents:
    """Pack-current distributions per payload level and slope.

    Parameters
    ----------
    samples_a : dict
        ``{slope: {payload_kg: samples}}`` with every slope of
        :data:`~battery_predictor.profiles.station.SLOPES` and the same
        payload levels (kg) for each slope; samples are pack currents in A
        (discharge positive).
    standstill_current_a : float
        Current in A while standing still (paper: 1.70 A).
    speed_m_s : float
        Travel speed in m/s the samples were measured at (paper: 0.50 m/s).
    stop_voltage_v : float
        Lowest pack voltage in V (paper: 45.00 V), for profile metadata.
    source : str
        Where the samples came from.

    Notes
    -----
    Each set gets a Gaussian KDE truncated to the set's range (so sampled
    currents stay within 0.50-7.30 A). Between payload levels,
    :meth:`mean_current_a` interpolates the sample means linearly and
    :meth:`sample_current_a` draws from the two neighbouring KDEs with the
    same linear weights. Payloads above the highest level use that level.
    """

    def __init__(
        self,
        samples_a: dict[str, dict[float, Sequence[float]]],
        *,
        standstill_current_a: float = 1.70,
        speed_m_s: float = DEFAULT_SPEED_M_S,
        stop_voltage_v: float = 45.0,
        source: str = "<memory>",
    ) -> None:
        if set(samples_a) != set(SLOPES):
            raise ProfileError(f"{source}: current samples must be given for exactly the slopes {SLOPES}")
        levels = sorted(float(p) for p in samples_a[FLAT])
        if not levels:
            raise ProfileError(f"{source}: no payload levels")
        for slope in SLOPES:
            if sorted(float(p) for p in samples_a[slope]) != levels:
                raise ProfileError(f"{source}: slope {slope} must have the payload levels {levels}")
        for level in levels:
            check_payload_kg(level)
        self.payload_levels_kg = np.array(levels)
        self.standstill_current_a = float(standstill_current_a)
        self.speed_m_s = float(speed_m_s)
        self.stop_voltage_v = float(stop_voltage_v)
        self.source = source
        self.samples_a: dict[tuple[str, float], np.ndarray] = {}
        self._kdes: dict[tuple[str, float], BoundedKde] = {}
        for slope in SLOPES:
            for payload, values in samples_a[slope].items():
                key = (slope, float(payload))
                arr = np.asarray(values, dtype=float)
                self.samples_a[key] = arr
                self._kdes[key] = BoundedKde(arr, name=f"{source}: {slope} {float(payload):g} kg currents")
        self._means = {
            slope: np.array([float(np.mean(self.samples_a[(slope, p)])) for p in levels]) for slope in SLOPES
        }
        self._stds = {
            slope: np.array([float(np.std(self.samples_a[(slope, p)], ddof=1)) for p in levels]) for slope in SLOPES
        }

    def kde(self, payload_level_kg: float, slope: str) -> BoundedKde:
        """The KDE of one measured (payload level, slope) set."""
        key = (check_slope(slope), float(payload_level_kg))
        if key not in self._kdes:
            raise ProfileError(f"{self.source}: no samples for {payload_level_kg:g} kg (levels {self.payload_levels_kg})")
        return self._kdes[key]

    def _neighbours(self, payload_kg: float) -> tuple[float, float, float]:
        """Lower level, upper level (kg) and weight of the upper one for ``payload_kg``."""
        payload = min(max(check_payload_kg(payload_kg), self.payload_levels_kg[0]), self.payload_levels_kg[-1])
        upper_index = int(np.searchsorted(self.payload_levels_kg, payload, side="left"))
        if self.payload_levels_kg[upper_index] == payload:
            level = float(payload)
            return level, level, 0.0
        low = float(self.payload_levels_kg[upper_index - 1])
        high = float(self.payload_levels_kg[upper_index])
        return low, high, (payload - low) / (high - low)

    def mean_current_a(self, payload_kg: float, slope: str) -> float:
        """Average pack current in A for ``payload_kg`` (kg) on ``slope``.

        The sample means of the payload levels are interpolated linearly;
        payloads outside the measured levels (0-80 kg) are clamped to them.

        Raises
        ------
        ProfileError
            For an unknown slope or a NaN, negative or > 200 kg payload.
        """
        check_slope(slope)
        payload = min(max(check_payload_kg(payload_kg), self.payload_levels_kg[0]), self.payload_levels_kg[-1])
        return float(np.interp(payload, self.payload_levels_kg, self._means[slope]))

    def std_current_a(self, payload_kg: float, slope: str) -> float:
        """Standard deviation in A of the measured currents for ``payload_kg`` (kg) on ``slope``.

        Interpolated between payload levels as :meth:`mean_current_a`.
        """
        check_slope(slope)
        payload = min(max(check_payload_kg(payload_kg), self.payload_levels_kg[0]), self.payload_levels_kg[-1])
        return float(np.interp(payload, self.payload_levels_kg, self._stds[slope]))

    def sample_current_a(self, payload_kg: float, slope: str, size: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``size`` pack currents in A for ``payload_kg`` on ``slope``."""
        check_slope(slope)
        low, high, weight = self._neighbours(payload_kg)
        if weight == 0.0:
            return self.kde(low, slope).sample(size, rng)
        use_high = rng.random(int(size)) < weight
        out = np.empty(int(size))
        out[~use_high] = self.kde(low, slope).sample(int((~use_high).sum()), rng)
        out[use_high] = self.kde(high, slope).sample(int(use_high.sum()), rng)
        return out

    def __repr__(self) -> str:
        return f"RangerCurrents({self.source!r}, payload levels {self.payload_levels_kg.tolist()} kg)"


def default_currents_path() -> Path:
    """Path of the shipped ``ranger_currents.yaml``."""
    return default_params_file(DEFAULT_CURRENTS_FILE)


def load_ranger_currents(path: str | Path | None = None) -> RangerCurrents:
    """Read a Ranger currents YAML (default: the shipped ``ranger_currents.yaml``).

    Raises
    ------
    ParamsError
        If a key is missing or unknown or a value invalid; the message names
        the file and the dotted key.
    """
    path, data = read_yaml_mapping(default_currents_path() if path is None else path)
    check_unknown(
        data, {"robot", "standstill_current_a", "speed_m_s", "stop_voltage_v", "payload_levels_kg", "samples_a"}, path, ""
    )
    standstill = as_float(require(data, "standstill_current_a", path, ""), path, "standstill_current_a",
                          minimum=0.0, strict=True)
    speed = as_float(require(data, "speed_m_s", path, ""), path, "speed_m_s", minimum=0.0, strict=True)
    stop_voltage = as_float(require(data, "stop_voltage_v", path, ""), path, "stop_voltage_v", minimum=0.0, strict=True)
    levels = as_float_list(require(data, "payload_levels_kg", path, ""), path, "payload_levels_kg",
                           minimum=0.0, min_length=1)
    if sorted(set(levels)) != levels:
        raise ParamsError(f"{path}: payload_levels_kg must be strictly increasing")
    if levels[-1] > MAX_PAYLOAD_KG:
        raise ParamsError(f"{path}: payload_levels_kg must not exceed {MAX_PAYLOAD_KG:g} kg")
    samples = require(data, "samples_a", path, "")
    check_unknown(samples, set(SLOPES), path, "samples_a")
    parsed: dict[str, dict[float, Sequence[float]]] = {}
    for slope in SLOPES:
        by_payload = require(samples, slope, path, "samples_a")
        if not isinstance(by_payload, dict):
            raise ParamsError(f"{path}: samples_a.{slope} must map payload_kg to a list of currents")
        parsed[slope] = {}
        for level in levels:
            key = next((k for k in by_payload if _same_number(k, level)), None)
            if key is None:
                raise ParamsError(f"{path}: missing key samples_a.{slope}.{level:g}")
            values = as_float_list(by_payload[key], path, f"samples_a.{slope}.{key}", minimum=0.0, strict=True)
            if len(set(values)) < 2:
                raise ParamsError(f"{path}: samples_a.{slope}.{key} needs at least two distinct currents")
            parsed[slope][level] = values
        extra = [k for k in by_payload if not any(_same_number(k, level) for level in levels)]
        if extra:
            raise ParamsError(f"{path}: unknown key samples_a.{slope}.{extra[0]} (not in payload_levels_kg)")
    try:
        return RangerCurrents(parsed, standstill_current_a=standstill, speed_m_s=speed, stop_voltage_v=stop_voltage,
                              source=str(path))
    except ProfileError as exc:
        raise ParamsError(str(exc)) from None


def _same_number(key: object, value: float) -> bool:
    try:
        return float(key) == value  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


@functools.lru_cache(maxsize=1)
def _default_currents() -> RangerCurrents:
    return load_ranger_currents()


def mean_current_a(payload_kg: float, slope: str, currents: RangerCurrents | None = None) -> float:
    """Average pack current in A for ``payload_kg`` (kg) on ``slope``.

    Uses ``currents`` or, by default, the shipped ``ranger_currents.yaml``.
    See :meth:`RangerCurrents.mean_current_a`.
    """
    return (currents or _default_currents()).mean_current_a(payload_kg, slope)


def std_current_a(payload_kg: float, slope: str, currents: RangerCurrents | None = None) -> float:
    """Standard deviation in A of the pack currents for ``payload_kg`` (kg) on ``slope``.

    Uses ``currents`` or, by default, the shipped ``ranger_currents.yaml``.
    See :meth:`RangerCurrents.std_current_a`.
    """
    return (currents or _default_currents()).std_current_a(payload_kg, slope)


@dataclass(frozen=True)
class RouteSection:
    """A part of a route with one slope and one payload.

    Attributes
    ----------
    name : str
        Section name, used as the label of its driving curve points.
    length_m : float
        Distance driven in m, >= 0 (0 for a pure standstill).
    slope : str
        ``flat``, ``uphill`` or ``downhill`` in the direction of travel.
    payload_kg : float
        Payload carried in kg, 0-200.
    speed_m_s : float
        Travel speed in m/s, > 0 (paper: 0.50 m/s).
    standstill_s : float
        Standstill after driving (e.g. loading at the section's end) in s,
        >= 0, one curve point at the standstill current. "After" as in the
        ``RouteSection.msg`` interface.
    leg : str
        Name of the route step the section belongs to (default: ``name``).
    """

    name: str
    length_m: float
    slope: str
    payload_kg: float
    speed_m_s: float = DEFAULT_SPEED_M_S
    standstill_s: float = 0.0
    leg: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ProfileError(f"route section name is {self.name!r} (must be a non-empty string)")
        try:
            check_slope(self.slope)
            object.__setattr__(self, "payload_kg", check_payload_kg(self.payload_kg))
        except ProfileError as exc:
            raise ProfileError(f"route section {self.name!r}: {exc}") from None
        for attr, strict in (("length_m", False), ("speed_m_s", True), ("standstill_s", False)):
            raw = getattr(self, attr)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise ProfileError(f"route section {self.name!r}: {attr} is {raw!r} (must be a number)") from None
            if not math.isfinite(value) or value < 0.0 or (strict and value == 0.0):
                relation = "> 0" if strict else ">= 0"
                raise ProfileError(f"route section {self.name!r}: {attr} is {raw!r} (must be finite and {relation})")
            object.__setattr__(self, attr, value)
        if self.length_m == 0.0 and self.standstill_s == 0.0:
            raise ProfileError(f"route section {self.name!r}: neither driving (length_m) nor standstill (standstill_s)")

    @property
    def travel_s(self) -> float:
        """Driving time in s."""
        return self.length_m / self.speed_m_s

    @property
    def duration_s(self) -> float:
        """Standstill plus driving time in s."""
        return self.standstill_s + self.travel_s

    @property
    def leg_name(self) -> str:
        """``leg`` if set, else ``name``."""
        return self.leg or self.name


@dataclass(frozen=True)
class Route:
    """An ordered sequence of route sections.

    Attributes
    ----------
    sections : tuple of RouteSection
        At least one section (any iterable is accepted and stored as tuple).
    name : str
        Route name, for metadata and plots.
    """

    sections: tuple[RouteSection, ...]
    name: str = ""

    def __post_init__(self) -> None:
        sections = tuple(self.sections) if isinstance(self.sections, Iterable) else ()
        if not sections:
            raise ProfileError(f"route {self.name!r}: it has no sections")
        for i, section in enumerate(sections):
            if not isinstance(section, RouteSection):
                raise ProfileError(f"route {self.name!r}: section {i} is a {type(section).__name__}, not a RouteSection")
        object.__setattr__(self, "sections", sections)

    def __len__(self) -> int:
        return len(self.sections)

    def __iter__(self) -> Iterator[RouteSection]:
        return iter(self.sections)

    @property
    def length_m(self) -> float:
        """Total distance in m."""
        return sum(s.length_m for s in self.sections)

    @property
    def travel_s(self) -> float:
        """Total driving time in s."""
        return sum(s.travel_s for s in self.sections)

    @property
    def standstill_s(self) -> float:
        """Total standstill time in s."""
        return sum(s.standstill_s for s in self.sections)

    @property
    def duration_s(self) -> float:
        """Total duration in s."""
        return self.travel_s + self.standstill_s

    def legs(self) -> list[tuple[str, tuple[RouteSection, ...]]]:
        """Consecutive sections grouped by :attr:`RouteSection.leg_name` (the route's steps)."""
        groups: list[tuple[str, list[RouteSection]]] = []
        for section in self.sections:
            if groups and groups[-1][0] == section.leg_name:
                groups[-1][1].append(section)
            else:
                groups.append((section.leg_name, [section]))
        return [(name, tuple(sections)) for name, sections in groups]


def route_from_station(
    station: Station,
    start: str,
    pickup: str,
    dropoff: str,
    payload_kg: float,
    *,
    speed_m_s: float = DEFAULT_SPEED_M_S,
    loading_s: float = DEFAULT_STANDSTILL_S,
    unloading_s: float = DEFAULT_STANDSTILL_S,
) -> Route:
    """Job route ``start -> pickup`` (unloaded) ``-> dropoff`` (loaded) ``-> start`` (unloaded).

    Every leg follows the shortest path on ``station``; each leg becomes one
    section per run of equal slope, named ``"<from>-><to> <slope>"`` (with
    `` 2``, `` 3``... appended when a slope recurs within the leg).

    Parameters
    ----------
    station : Station
        The station graph.
    start : str
        Where the robot waits and returns to (normally ``charger``).
    pickup, dropoff : str
        Where the luggage is loaded and unloaded.
    payload_kg : float
        Luggage mass in kg (0-200).
    speed_m_s : float
        Travel speed in m/s.
    loading_s, unloading_s : float
        Standstill in s at the pickup (after the last section of the
        unloaded first leg) and at the dropoff (after the last section of the
        loaded leg), each one curve point at the standstill current. The
        paper's :func:`longest_route` places the same 2 x 60 s at the very
        start and end instead; point count, total duration and charge are
        the same.

    Raises
    ------
    ProfileError
        For unknown locations, ``pickup == dropoff``, unreachable locations,
        or an invalid payload.
    """
    check_payload_kg(payload_kg)
    for node in (start, pickup, dropoff):
        station.check_node(node)
    if pickup == dropoff:
        raise ProfileError(f"route: pickup and dropoff are both {pickup!r}")
    legs = ((start, pickup, 0.0, loading_s), (pickup, dropoff, payload_kg, unloading_s), (dropoff, start, 0.0, 0.0))
    sections: list[RouteSection] = []
    for origin, goal, payload, standstill in legs:
        leg = f"{origin}->{goal}"
        path = station.shortest_path(origin, goal)
        if not path.segments:
            if standstill > 0.0:  # e.g. loading right where the robot waits
                name = f"standstill at {goal}"
                sections.append(RouteSection(name, 0.0, FLAT, payload, speed_m_s, standstill, name))
            continue
        seen: dict[str, int] = {}
        for i, segment in enumerate(path.segments):
            seen[segment.slope] = seen.get(segment.slope, 0) + 1
            suffix = f" {seen[segment.slope]}" if seen[segment.slope] > 1 else ""
            sections.append(
                RouteSection(
                    f"{leg} {segment.slope}{suffix}",
                    segment.length_m,
                    segment.slope,
                    payload,
                    speed_m_s,
                    standstill if i == len(path.segments) - 1 else 0.0,
                    leg,
                )
            )
    return Route(tuple(sections), name=f"{start}: {pickup} -> {dropoff} with {float(payload_kg):g} kg")


def longest_route(payload_kg: float = 80.0, *, speed_m_s: float = DEFAULT_SPEED_M_S,
                  standstill_s: float = DEFAULT_STANDSTILL_S) -> Route:
    """The paper's longest route (section 5.2.2) in its 5 steps.

    1. 60 s standstill (one curve point);
    2. charger -> platform 11 south: 190 m flat, unloaded (380 s);
    3. platform 11 south -> platform 13 south: 345 m flat (690 s) then 75 m
       uphill (150 s), loaded with ``payload_kg``;
    4. platform 13 south -> charger: 75 m downhill (150 s) then 205 m flat
       (410 s), unloaded;
    5. 60 s standstill (one curve point).

    At 0.50 m/s this is 29.67 min of travel plus 2 min standstill = 31.67 min,
    and :func:`route_profile` makes 97 curve points of it.
    """
    step2, step3, step4 = "charger->platform11_south", "platform11_south->platform13_south", "platform13_south->charger"
    sections = (
        RouteSection("standstill start", 0.0, FLAT, 0.0, speed_m_s, standstill_s, "step 1: standstill"),
        RouteSection(f"{step2} flat", 190.0, FLAT, 0.0, speed_m_s, 0.0, f"step 2: {step2}"),
        RouteSection(f"{step3} flat", 345.0, FLAT, payload_kg, speed_m_s, 0.0, f"step 3: {step3}"),
        RouteSection(f"{step3} uphill", 75.0, "uphill", payload_kg, speed_m_s, 0.0, f"step 3: {step3}"),
        RouteSection(f"{step4} downhill", 75.0, "downhill", 0.0, speed_m_s, 0.0, f"step 4: {step4}"),
        RouteSection(f"{step4} flat", 205.0, FLAT, 0.0, speed_m_s, 0.0, f"step 4: {step4}"),
        RouteSection("standstill end", 0.0, FLAT, 0.0, speed_m_s, standstill_s, "step 5: standstill"),
    )
    return Route(sections, name=f"longest route with {float(payload_kg):g} kg")


def curve_points_for(travel_s: float, point_duration_s: float = DEFAULT_POINT_DURATION_S) -> int:
    """Number of equal curve points a driving time of ``travel_s`` (s) is split into.

    ``ceil(travel_s / point_duration_s)`` (at least 1), so no point is longer
    than ``point_duration_s``; a tolerance of 1e-9 keeps exact multiples
    (380 s / 19 s = 20) from gaining a point through rounding errors.
    """
    if not (math.isfinite(point_duration_s) and point_duration_s > 0.0):
        raise ProfileError(f"point_duration_s is {point_duration_s} (must be finite and > 0)")
    return max(1, math.ceil(travel_s / point_duration_s - 1e-9))


def route_profile(
    route: Route,
    currents: RangerCurrents | None = None,
    seed: int | np.random.Generator | None = None,
    point_duration_s: float = DEFAULT_POINT_DURATION_S,
    mode: str = "sampled",
) -> LoadProfile:
    """Load profile of a route (section 5.2.2).

    Parameters
    ----------
    route : Route
        The route.
    currents : RangerCurrents, optional
        Current distributions (default: the shipped ``ranger_currents.yaml``).
    seed : int, numpy.random.Generator or None
        Randomness for ``mode="sampled"`` (ignored for ``"mean"``).
    point_duration_s : float
        Target curve-point duration in s; driving is split with
        :func:`curve_points_for` (ceil rule, every point <= 19 s).
    mode : {"sampled", "mean"}
        ``"sampled"`` draws each point's current from the (payload, slope)
        KDE, as for the paper's experiments; ``"mean"`` uses
        :meth:`RangerCurrents.mean_current_a`, as the predictor does
        (section 5.2.4).

    Returns
    -------
    LoadProfile
        Driving points are labelled with their section name, standstill
        points with ``"standstill"`` (at the standstill current, 1.70 A).
        Metadata: robot, route, mode, seed, point_duration_s, legs,
        points_per_section, standstill_current_a, stop_voltage_v. A
        section's standstill point follows its driving points.
    """
    if not isinstance(route, Route):
        raise ProfileError(f"route_profile needs a Route, got {type(route).__name__}")
    if mode not in ("sampled", "mean"):
        raise ProfileError(f"route profile mode is {mode!r} (expected 'sampled' or 'mean')")
    currents = currents or _default_currents()
    point_duration_s = float(point_duration_s)
    rng = np.random.default_rng(seed) if mode == "sampled" else None
    durations: list[np.ndarray] = []
    values: list[np.ndarray] = []
    labels: list[str] = []
    points_per_section: list[int] = []
    for section in route.sections:
        n_section = 0
        if section.length_m > 0.0:
            n = curve_points_for(section.travel_s, point_duration_s)
            durations.append(np.full(n, section.travel_s / n))
            if rng is None:
                values.append(np.full(n, currents.mean_current_a(section.payload_kg, section.slope)))
            else:
                values.append(currents.sample_current_a(section.payload_kg, section.slope, n, rng))
            labels.extend([section.name] * n)
            n_section += n
        if section.standstill_s > 0.0:
            durations.append(np.array([section.standstill_s]))
            values.append(np.array([currents.standstill_current_a]))
            labels.append(STANDSTILL_LABEL)
            n_section += 1
        points_per_section.append(n_section)
    metadata = {
        "robot": "ranger_mini",
        "route": route.name,
        "mode": mode,
        "seed": int(seed) if isinstance(seed, int | np.integer) and mode == "sampled" else None,
        "point_duration_s": point_duration_s,
        "legs": [name for name, _ in route.legs()],
        "points_per_section": points_per_section,
        "standstill_current_a": currents.standstill_current_a,
        "stop_voltage_v": currents.stop_voltage_v,
        "currents": currents.source,
    }
    return LoadProfile(np.concatenate(durations), np.concatenate(values), tuple(labels), metadata)


def stepwise_profile(
    currents_a: Sequence[float] = (0.5, 1, 2, 3, 4, 5, 6, 7, 8),
    step_s: float = 600.0,
    *,
    stop_voltage_v: float = 45.0,
) -> LoadProfile:
    """The stepwise experiment of section 5.2.2: each current for ``step_s`` (s).

    One pass (0.5, 1, 2, ..., 8 A for 10 min each) draws only ~6.1 Ah of the
    24 Ah pack, so the experiment repeats the steps until the terminal
    voltage reaches ``stop_voltage_v``. Whoever simulates or emulates the
    profile applies that stop; the metadata says so with
    ``{"stop_voltage_v": 45.0, "repeat_until_stop": True}`` (use
    :meth:`LoadProfile.repeat` to unroll enough passes).
    """
    values = np.asarray(currents_a, dtype=float)
    if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values)) or np.any(values <= 0.0):
        raise ProfileError(f"stepwise profile: currents_a must be finite and > 0 A, got {list(currents_a)}")
    step_s = float(step_s)
    if not math.isfinite(step_s) or step_s <= 0.0:
        raise ProfileError(f"stepwise profile: step_s is {step_s} (must be finite and > 0)")
    metadata = {
        "robot": "ranger_mini",
        "kind": "stepwise",
        "step_s": step_s,
        "stop_voltage_v": float(stop_voltage_v),
        "repeat_until_stop": True,
    }
    labels = tuple(f"{c:g} A" for c in values)
    return LoadProfile(np.full(values.size, step_s), values, labels, metadata)
