"""``fit``'s default data preparation: data denser than the battery monitor's window are averaged over it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.cli.common import prepared_data
from battery_predictor.cli.main import build_parser
from battery_predictor.errors import InputDataError
from battery_predictor.fitting.resample import MONITOR_WINDOW_S, as_the_monitor_sees, median_interval_s
from battery_predictor.io.csv_io import save_csv
from battery_predictor.monitor.core import MonitorConfig
from battery_predictor.params import load_params
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]


def _recording(step_s: float, duration_s: float = 600.0, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, step_s)
    return Recording(t, 4.1 - 1e-4 * t + rng.normal(0.0, 0.002, t.size), rng.uniform(0.5, 5.0, t.size),
                     source=f"every_{step_s:g}_s")


def test_the_default_window_is_the_monitors():
    assert MONITOR_WINDOW_S == MonitorConfig().window_s == 5.0


def test_data_denser_than_the_monitor_window_are_averaged_over_it_and_it_says_so():
    rec = _recording(1.0)
    out, window_s, notice = as_the_monitor_sees([rec])
    assert window_s == MONITOR_WINDOW_S
    assert median_interval_s(out[0]) == pytest.approx(MONITOR_WINDOW_S)
    assert out[0].time_s[0] == rec.time_s[0] and out[0].voltage_v[0] == rec.voltage_v[0]
    assert "5 s windows" in notice and "every 1 s" in notice and "--no-resample" in notice


def test_data_at_the_monitor_window_or_coarser_are_kept_as_they_are():
    for step_s in (MONITOR_WINDOW_S, 10.0):
        rec = _recording(step_s)
        out, window_s, notice = as_the_monitor_sees([rec])
        assert out[0] is rec and window_s is None and notice is None


def test_one_dense_file_among_coarse_ones_averages_them_all():
    coarse, dense = _recording(10.0), _recording(0.5, seed=1)
    out, window_s, notice = as_the_monitor_sees([coarse, dense])
    assert window_s == MONITOR_WINDOW_S and "every 0.5 s" in notice
    np.testing.assert_allclose(out[0].voltage_v, coarse.voltage_v)  # 10 s samples: one per 5 s window
    assert median_interval_s(out[1]) == pytest.approx(MONITOR_WINDOW_S)


def test_no_resample_keeps_the_samples_and_an_explicit_window_wins():
    rec = _recording(1.0)
    out, window_s, notice = as_the_monitor_sees([rec], as_measured=True)
    assert out[0] is rec and window_s is None and notice is None
    out, window_s, notice = as_the_monitor_sees([rec], 10.0)
    assert window_s == 10.0 and notice is None and median_interval_s(out[0]) == pytest.approx(10.0)
    with pytest.raises(InputDataError, match="--no-resample"):
        as_the_monitor_sees([rec], 10.0, as_measured=True)


@pytest.mark.parametrize(("extra", "window_s", "said"), [((), 5.0, True), (("--no-resample",), None, False),
                                                          (("--resample", "10"), 10.0, False)])
@pytest.mark.parametrize("command", ["fit", "simulate"])
def test_fit_and_simulate_prepare_one_second_data_as_the_monitor_sees_them(tmp_path, capsys, extra, window_s, said,
                                                                            command):
    csv = tmp_path / "one_second.csv"
    save_csv(_recording(1.0), csv)
    out = ["--out", "f.yaml"] if command == "fit" else []
    args = build_parser().parse_args([command, "--params", "p.yaml", "--data", str(csv), *out, *extra])
    params = load_params(REPO / "params" / "panasonic_18650pf.yaml")
    recs = prepared_data(args, params, command=command)
    assert args.resample == window_s  # what the provenance / the JSON records
    assert median_interval_s(recs[0]) == pytest.approx(window_s or 1.0)
    err = capsys.readouterr().err
    assert (f"{command}: averaging the data over 5 s windows" in err) is said
