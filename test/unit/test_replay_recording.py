"""A replay stream's messages as a recording: the same as reading the bag again, and the replay's measured truth.

``ReplayStream.recording`` decodes the messages a replay already holds with the bag reader's own
decoding (:func:`battery_predictor.io.bags.reader.recording_from_messages`); ``replay``'s
``measured_truth`` scores a bag without lab truth on it instead of reading the bag from disk again.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.cli.cmd_replay import measured_truth
from battery_predictor.config import default_params_file
from battery_predictor.evaluation.runtime_eval import recording_runtime_truth
from battery_predictor.io.bags import read_recording_bag, write_recording_bag
from battery_predictor.params import load_params
from battery_predictor.recording import Recording
from battery_predictor.replay import RuntimePoint, read_replay_stream

REPO = Path(__file__).resolve().parents[2]


def _measured(path: Path, style: str, *, gaps: bool = False) -> Path:
    """40 min at 5 s reaching the temi cut-off (13.30 V at 2208 s), no truth metadata."""
    t = np.arange(0.0, 2400.0, 5.0)
    v = 15.6 - 2.5 * t / 2400.0
    i = np.where((t // 300) % 2 == 0, 1.5, 3.0)
    temp = np.full(t.size, 297.0)
    if gaps:
        v[7] = 0.0  # the writer refuses NaN; the reader drops a voltage <= 0 with drop_nan
        temp[11] = math.nan
    write_recording_bag(Recording(t, v, i, temp, source="m"), path, style=style, metadata={"site": "bench"})
    return path


def _same(a: Recording, b: Recording) -> None:
    np.testing.assert_array_equal(a.time_s, b.time_s)
    np.testing.assert_array_equal(a.voltage_v, b.voltage_v)
    np.testing.assert_array_equal(a.current_a, b.current_a)
    np.testing.assert_array_equal(a.temperature_k, b.temperature_k)
    assert a.metadata == b.metadata and a.source == b.source


@pytest.mark.parametrize("style", ["relay", "battery_state"])
@pytest.mark.parametrize("gaps", [False, True])
def test_stream_recording_equals_reading_the_bag(tmp_path, style, gaps):
    bag = _measured(tmp_path / f"{style}_bag", style, gaps=gaps)
    _same(read_replay_stream(bag).recording(drop_nan=True), read_recording_bag(bag, drop_nan=True))


@pytest.mark.parametrize("name", ["temi_dynamic_pack1", "ranger_route_20kg_pack1"])
def test_stream_recording_equals_reading_a_shipped_bag(name):
    bag = REPO / "bags" / name
    _same(read_replay_stream(bag).recording(), read_recording_bag(bag))


def test_stream_recording_refuses_bad_samples_as_the_reader_does(tmp_path):
    from battery_predictor.errors import InputDataError

    bag = _measured(tmp_path / "bag", "relay", gaps=True)
    with pytest.raises(InputDataError) as from_stream:
        read_replay_stream(bag).recording()
    with pytest.raises(InputDataError) as from_bag:
        read_recording_bag(bag)
    assert str(from_stream.value) == str(from_bag.value)


def _point(cutoff_v: float) -> RuntimePoint:
    return RuntimePoint(time_s=100.0, remaining_s=600.0, valid=True, status=0, cutoff_voltage_v=cutoff_v)


def test_measured_truth_from_the_stream_is_the_truth_of_the_bag(tmp_path):
    bag = _measured(tmp_path / "bag", "relay")
    stream = read_replay_stream(bag)
    pack = load_params(default_params_file("temi.yaml"))
    truth = measured_truth(stream, pack, [_point(math.nan), _point(13.30)])
    rec = read_recording_bag(bag, drop_nan=True)
    expected = recording_runtime_truth(pack, rec, 13.30,
                                       time_offset_s=stream.recording_time_s(stream.start_ns) - float(rec.time_s[0]))
    assert truth is not None and expected is not None
    assert truth == expected
    assert truth.runtime_s == pytest.approx(2208.0, abs=10.0)


def test_measured_truth_needs_a_pack_and_a_published_cutoff(tmp_path):
    stream = read_replay_stream(_measured(tmp_path / "bag", "relay"))
    pack = load_params(default_params_file("temi.yaml"))
    assert measured_truth(stream, None, [_point(13.30)]) is None
    assert measured_truth(stream, pack, [_point(math.nan), _point(0.0)]) is None
