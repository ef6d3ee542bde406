"""Load profiles: curve-point sequences for the Temi and Ranger Mini robots.

* :mod:`.load_profile` -- the :class:`LoadProfile` data type (CSV I/O, sampling).
* :mod:`.temi` -- stochastic information-robot profiles (seed paper 5.1.1-5.1.4).
* :mod:`.station` -- Minden station graph and shortest paths (sections 3, 5.2.2).
* :mod:`.ranger` -- luggage-robot routes, route profiles, stepwise experiment (5.2.1-5.2.2).
* :mod:`.psu_export` -- sequences of <= 99 points for the EA PSB 10060-120.
* :mod:`.plot` -- step plot of a profile (imported on demand, needs matplotlib).
"""

from battery_predictor.profiles.load_profile import LoadProfile, constant_current_profile
from battery_predictor.profiles.psu_export import PsuSequence, psu_sequences, write_psu_csv
from battery_predictor.profiles.ranger import (
    RangerCurrents,
    Route,
    RouteSection,
    load_ranger_currents,
    longest_route,
    mean_current_a,
    route_from_station,
    route_profile,
    stepwise_profile,
)
from battery_predictor.profiles.station import SLOPES, Station, StationPath, load_station
from battery_predictor.profiles.temi import (
    TemiUsageConfig,
    derive_usage_probabilities,
    generate_usage_profile,
    load_usage_config,
)

__all__ = [
    "SLOPES",
    "LoadProfile",
    "PsuSequence",
    "RangerCurrents",
    "Route",
    "RouteSection",
    "Station",
    "StationPath",
    "TemiUsageConfig",
    "constant_current_profile",
    "derive_usage_probabilities",
    "generate_usage_profile",
    "load_ranger_currents",
    "load_station",
    "load_usage_config",
    "longest_route",
    "mean_current_a",
    "psu_sequences",
    "route_from_station",
    "route_profile",
    "stepwise_profile",
    "write_psu_csv",
]
