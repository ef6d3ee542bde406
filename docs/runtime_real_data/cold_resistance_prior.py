"""A-priori cold charge-transfer resistance for the Panasonic 18650PF from another graphite cell's pulses.

The ``temperature`` extension's Arrhenius charge-transfer resistance (``COLD_CHARGE_TRANSFER``) adds
``R (exp(E/R (1/T - 1/T_anchor)) - 1)`` (E = 30 kJ/mol) to the cell's resistance below the anchor. 25 degC
drive cycles cannot identify ``R``; like the cold-window prior, it is taken from the LG M50 (graphite anode,
``../shared/data/lgm50_wmg``, PROVENANCE.md there), whose 10 s discharge pulses were measured at 0, 10, 25 and
45 degC (2.5 A at 0 degC, 7.5 A elsewhere; 9 SoC levels, 6 cells per temperature, other cells at each
temperature):

1. per pulse ``(V_rest - V(t)) / I`` at 1 s and 10 s after the pulse starts (``V_rest``: the record's
   last rest sample, ``I``: the pulse's median current); the median over the cells per SoC label and
   temperature;
2. the growth ``R(T) - R(25 degC)`` at mid SoC (SoC3..SoC7), fitted by least squares through the origin to
   ``R_ct (arrhenius_ratio(30 kJ/mol, T, T_25) - 1)`` at each set's measured median temperature;
3. the fraction ``f = R_ct / R_25`` (the LG M50's own 1 s resistance at 25 degC, mid SoC), and the
   Panasonic's prior ``f`` times its 1 s step resistance on the two 25 degC fit recordings
   (``recording.step_resistance_ohm``).

Usage::

    python docs/runtime_real_data/cold_resistance_prior.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from battery_predictor.io.loader import load_recording
from battery_predictor.recording import step_resistance_ohm
from battery_predictor.simulation.extensions import COLD_RESISTANCE_ACTIVATION_J_MOL, arrhenius_ratio

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
#: The LG M50 pulse sets (nominal chamber temperature degC, file).
PULSE_SETS = ((0, "pulses_T00C.csv"), (10, "pulses_T10C.csv"), (25, "pulses_T25C.csv"), (45, "pulses_T45C.csv"))
#: The SoC labels of the fit (mid SoC, where the charge-transfer shape is close to 1).
MID_SOC = ("SoC3", "SoC4", "SoC5", "SoC6", "SoC7")
#: The Panasonic's 25 degC fit recordings (README, "With `fit` at its default settings").
PANASONIC_FIT = ("drive_T25C_HWFET.csv", "drive_T25C_LA92.csv")
KELVIN = 273.15


def pulse_resistances(path: Path, at_s: Sequence[float] = (1.0, 10.0)) -> list[dict]:
    """Each pulse record's ``(V_rest - V(t)) / I`` (Ohm) at ``at_s`` seconds, its SoC label, cell and temperature.

    The pulse starts at the first sample after the rest sample whose current exceeds half the pulse current or
    whose voltage lies 5 mV below the rest voltage. A value is NaN when the record ends before it (a few 10 degC
    records are under 1 s long); the 10 s value is taken at the last loaded sample when the pulse ends up to
    0.1 s before 10 s.
    """
    records: dict[tuple[str, str], list[dict]] = defaultdict(list)
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            records[(row["soc_label"], row["cell"])].append(row)
    out = []
    for (soc, cell), rows in records.items():
        t = np.array([float(r["time_s"]) for r in rows])
        i = np.array([float(r["current_A"]) for r in rows])
        v = np.array([float(r["voltage_V"]) for r in rows])
        temps = [float(r["temperature_C"]) for r in rows if r["temperature_C"] != ""]
        v_rest, i_pulse = v[0], float(np.max(i))
        loaded = i > 0.5 * i_pulse
        started = loaded | (v < v_rest - 0.005)
        started[0] = False
        t0 = t[int(np.argmax(started))]
        tl, keep = np.unique(t[loaded] - t0, return_index=True)
        vl = v[loaded][keep]
        current = float(np.median(i[loaded]))
        values = {}
        for at in at_s:
            if tl.size == 0 or tl[-1] < at - 0.1:
                values[at] = float("nan")
            else:
                values[at] = (v_rest - float(np.interp(min(at, tl[-1]), tl, vl))) / current
        out.append({"soc": soc, "cell": cell, "current_a": current, "r": values,
                    "temperature_c": float(np.median(temps)) if temps else float("nan")})
    return out


def median_table(pulses: list[dict], at: float) -> dict[str, float]:
    """Median over the cells of the resistance at ``at`` s per SoC label (Ohm; NaN-free labels only)."""
    by_soc: dict[str, list[float]] = defaultdict(list)
    for p in pulses:
        if np.isfinite(p["r"][at]):
            by_soc[p["soc"]].append(p["r"][at])
    return {soc: float(np.median(vals)) for soc, vals in sorted(by_soc.items())}


def derive(data: Path = DATA, socs: Sequence[str] = MID_SOC) -> dict:
    """The derivation's numbers: the tables, ``R_ct`` and ``f`` at 1 s and 10 s, and the Panasonic prior (Ohm)."""
    sets = {nominal: pulse_resistances(data / "lgm50_wmg" / name) for nominal, name in PULSE_SETS}
    temps_c = {nominal: float(np.nanmedian([p["temperature_c"] for p in pulses])) for nominal, pulses in sets.items()}
    currents = {nominal: float(np.median([p["current_a"] for p in pulses])) for nominal, pulses in sets.items()}
    result: dict = {"temperature_c": temps_c, "current_a": currents, "at": {}}
    anchor_k = temps_c[25] + KELVIN
    for at in (1.0, 10.0):
        tables = {nominal: median_table(pulses, at) for nominal, pulses in sets.items()}
        x, y, per_t = [], [], {}
        for nominal in (0, 10, 45):
            excess = arrhenius_ratio(COLD_RESISTANCE_ACTIVATION_J_MOL, temps_c[nominal] + KELVIN, anchor_k) - 1.0
            growth = [tables[nominal][s] - tables[25][s] for s in socs]
            x += [excess] * len(growth)
            y += growth
            per_t[nominal] = float(np.mean(growth) / excess)
        r_ct = float(np.dot(x, y) / np.dot(x, x))
        mid = {nominal: float(np.median([table[s] for s in socs])) for nominal, table in tables.items()}
        result["at"][at] = {"tables": tables, "mid_soc_ohm": mid, "r_ct_ohm": r_ct, "r_ct_per_temperature_ohm": per_t,
                            "r_25_ohm": mid[25], "fraction": r_ct / mid[25]}
    recordings = [load_recording(data / "panasonic_18650pf" / name) for name in PANASONIC_FIT]
    result["panasonic_step_ohm"] = step_resistance_ohm(recordings)
    result["prior_ohm"] = result["at"][1.0]["fraction"] * result["panasonic_step_ohm"]
    return result


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help="folder holding lgm50_wmg/ and panasonic_18650pf/")
    args = parser.parse_args(argv)
    res = derive(args.data)
    temps = ", ".join(f"{n} degC set: {t:.1f} degC, {res['current_a'][n]:.2f} A" for n, t in res["temperature_c"].items())
    print(f"LG M50 pulses (median measured temperature, pulse current): {temps}")
    for at, part in res["at"].items():
        print(f"\n(V_rest - V({at:g} s)) / I, median over cells (mOhm):")
        print("SoC   " + "".join(f"{n:>8d}" for n in part["tables"]))
        for soc in sorted(part["tables"][25]):
            print(f"{soc:6s}" + "".join(f"{1e3 * t.get(soc, float('nan')):8.1f}" for t in part["tables"].values()))
        mid = ", ".join(f"{n} degC {1e3 * r:.1f}" for n, r in part["mid_soc_ohm"].items())
        print(f"median over {MID_SOC[0]}..{MID_SOC[-1]} (mOhm): {mid}")
        per_t = ", ".join(f"{n} degC {1e3 * r:.2f}" for n, r in part["r_ct_per_temperature_ohm"].items())
        print(f"R_ct ({MID_SOC[0]}..{MID_SOC[-1]}, least squares) {1e3 * part['r_ct_ohm']:.2f} mOhm "
              f"(each temperature alone: {per_t}); R_25 {1e3 * part['r_25_ohm']:.2f} mOhm; "
              f"f = {part['fraction']:.3f}")
    print(f"\nPanasonic 1 s step resistance on its 25 degC fit recordings: {1e3 * res['panasonic_step_ohm']:.2f} mOhm")
    print(f"Prior: f(1 s) x step = {1e3 * res['prior_ohm']:.2f} mOhm")


if __name__ == "__main__":
    main()
