"""rosbag2 MCAP recordings: round trips, topic styles, metadata, corrupt bags, loader and the ``bag`` CLI."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from battery_predictor.cli.main import main
from battery_predictor.errors import BagError, BatteryPredictorError, InputDataError
from battery_predictor.io.bags import (
    BATTERY_STATE_TYPE,
    DEFAULT_START_NS,
    bag_info,
    read_recording_bag,
    write_recording_bag,
)
from battery_predictor.io.csv_io import load_csv, save_csv
from battery_predictor.io.loader import bag_to_csv, csv_to_bag, load_recording
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
TS = get_typestore(Stores.ROS2_JAZZY)


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def make_recording(seed: int = 0, n: int = 400, *, temperature: bool = True, t0: float = 0.0) -> Recording:
    """Pulsed discharge of a 14.4 V pack sampled at ~10 Hz with ms-resolution times."""
    rng = np.random.default_rng(seed)
    t = t0 + np.round(np.cumsum(rng.uniform(0.08, 0.12, n)), 3)
    i = np.where(np.arange(n) < 20, 0.05, 1.5 + 1.0 * (np.arange(n) // 50 % 2)) + rng.normal(0, 0.01, n)
    v = 15.8 - 0.002 * np.arange(n) - 0.08 * i + rng.normal(0, 1e-3, n)
    temp_k = 296.15 + 0.001 * np.arange(n) + rng.normal(0, 0.02, n) if temperature else None
    return Recording(time_s=t, voltage_v=v, current_a=i, temperature_k=temp_k, source="synthetic")


def assert_float32_equal(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(np.asarray(a, np.float32), np.asarray(b, np.float32))


def the_mcap(bag: Path) -> Path:
    (mcap,) = bag.glob("*.mcap")
    return mcap


def write_raw_bag(path: Path, topics: dict[str, tuple[str, list[tuple[int, object]]]]) -> Path:
    """Write messages directly with rosbags: {topic: (msgtype, [(log_ns, msg), ...])}."""
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conns = {name: writer.add_connection(name, msgtype, typestore=TS) for name, (msgtype, _) in topics.items()}
    events = sorted((ns, name, msg) for name, (_, msgs) in topics.items() for ns, msg in msgs)
    for ns, name, msg in events:
        writer.write(conns[name], ns, TS.serialize_cdr(msg, topics[name][0]))
    writer.close()
    return path


def battery_state_msg(ns: int, voltage: float, current: float, temperature: float = float("nan")):
    cls = TS.types[BATTERY_STATE_TYPE]
    header = TS.types["std_msgs/msg/Header"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id="bms"
    )
    nan = float("nan")
    return cls(
        header=header, voltage=voltage, temperature=temperature, current=current, charge=nan, capacity=nan,
        design_capacity=nan, percentage=nan, power_supply_status=0, power_supply_health=0,
        power_supply_technology=0, present=True, cell_voltage=np.zeros(0, np.float32),
        cell_temperature=np.zeros(0, np.float32), location="", serial_number="",
    )


def float_msg(value: float, msgtype: str = "std_msgs/msg/Float64"):
    return TS.types[msgtype](data=value)


def bag_error(path, match: str | None = None, **kwargs) -> str:
    with pytest.raises(BagError) as info:
        read_recording_bag(path, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg, "error messages must be one line"
    assert str(path) in msg, "error messages must name the bag"
    if match:
        assert match in msg, msg
    return msg


@pytest.fixture
def recording() -> Recording:
    return make_recording(1)


@pytest.fixture
def relay_bag(tmp_path: Path, recording: Recording) -> Path:
    return write_recording_bag(recording, tmp_path / "relay_bag", style="relay", metadata={"pack_id": "temi-1"})


@pytest.fixture
def state_bag(tmp_path: Path, recording: Recording) -> Path:
    return write_recording_bag(recording, tmp_path / "state_bag", style="battery_state", metadata={"pack_id": "ranger-1"})


# ---------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------


def test_relay_round_trip_is_bit_identical_with_metadata(tmp_path: Path, recording: Recording) -> None:
    meta = {"pack_id": "temi-1", "profile_seed": 42, "generator_version": "0.1.0", "truth": {"time_to_cutoff_s": 1234.5}}
    bag = write_recording_bag(recording, tmp_path / "relay", style="relay", metadata=meta)
    assert (bag / "metadata.yaml").is_file() and the_mcap(bag).is_file()
    back = read_recording_bag(bag)
    assert np.array_equal(back.time_s, recording.time_s)
    assert np.array_equal(back.voltage_v, recording.voltage_v)
    assert np.array_equal(back.current_a, recording.current_a)
    np.testing.assert_allclose(back.temperature_k, recording.temperature_k, rtol=0, atol=1e-9)
    assert back.metadata == meta
    assert back.source == str(bag)


def test_battery_state_round_trip_is_identical_within_float32(state_bag: Path, recording: Recording) -> None:
    back = read_recording_bag(state_bag)
    assert np.array_equal(back.time_s, recording.time_s)
    assert_float32_equal(back.voltage_v, recording.voltage_v)
    assert_float32_equal(back.current_a, recording.current_a)
    np.testing.assert_allclose(back.temperature_k, recording.temperature_k, rtol=0, atol=2e-5)
    assert back.metadata == {"pack_id": "ranger-1"}


def test_battery_state_messages_carry_negative_current_while_discharging(state_bag: Path, recording: Recording) -> None:
    with Reader(state_bag) as reader:
        msgs = [TS.deserialize_cdr(raw, conn.msgtype) for conn, _, raw in reader.messages()]
    currents = np.array([m.current for m in msgs])
    assert_float32_equal(currents, -recording.current_a)
    assert all(m.power_supply_status == m.POWER_SUPPLY_STATUS_DISCHARGING for m in msgs)
    assert msgs[0].temperature == pytest.approx(recording.temperature_k[0] - 273.15, abs=1e-4)  # °C in the message


def test_recording_without_temperature_round_trips_to_none_in_both_styles(tmp_path: Path) -> None:
    rec = make_recording(2, temperature=False)
    for style in ("relay", "battery_state"):
        bag = write_recording_bag(rec, tmp_path / style, style=style)
        assert read_recording_bag(bag).temperature_k is None
    topics = {t["name"] for t in bag_info(tmp_path / "relay")["topics"]}
    assert topics == {"/battery/voltage", "/battery/current"}


def test_single_mcap_file_reads_like_the_directory(relay_bag: Path, state_bag: Path) -> None:
    for bag in (relay_bag, state_bag):
        a = read_recording_bag(bag)
        b = read_recording_bag(the_mcap(bag))
        assert np.array_equal(a.time_s, b.time_s) and np.array_equal(a.voltage_v, b.voltage_v)
        assert a.metadata == b.metadata  # custom_data also comes from the MCAP metadata record


def test_epoch_time_axis_is_kept(tmp_path: Path) -> None:
    rec = make_recording(3, t0=1_750_000_000.0)
    back = read_recording_bag(write_recording_bag(rec, tmp_path / "epoch", style="relay"))
    np.testing.assert_allclose(back.time_s, rec.time_s, rtol=0, atol=1e-6)
    assert bag_info(tmp_path / "epoch")["start"].startswith("2025-06-15")


def test_relative_time_axis_is_anchored_at_the_documented_start(relay_bag: Path, recording: Recording) -> None:
    info = bag_info(relay_bag)
    assert info["start_ns"] == DEFAULT_START_NS + round(recording.time_s[0] * 1e9)  # time_s = 0 at 2024-01-01
    assert info["duration_s"] == pytest.approx(recording.duration_s, abs=1e-9)


def test_custom_topic_names_are_used_and_detected(tmp_path: Path, recording: Recording) -> None:
    bag = write_recording_bag(recording, tmp_path / "ns", style="relay", topic_prefix="/temi/pack")
    assert {t["name"] for t in bag_info(bag)["topics"]} == {"/temi/pack/voltage", "/temi/pack/current", "/temi/pack/temperature"}
    assert len(read_recording_bag(bag).time_s) == len(recording.time_s)
    bag2 = write_recording_bag(recording, tmp_path / "bs", topic_prefix="/ranger/battery")
    assert read_recording_bag(bag2, topic="/ranger/battery").metadata == {}


# ---------------------------------------------------------------------------
# robot-style bags written by other tools
# ---------------------------------------------------------------------------


def test_foreign_battery_state_bag_converts_sign_and_celsius(tmp_path: Path) -> None:
    start = 1_760_000_000 * 10**9
    msgs = [(start + k * 10**8, battery_state_msg(start + k * 10**8, 50.0 - 0.01 * k, -3.0, 21.5)) for k in range(50)]
    bag = write_raw_bag(tmp_path / "ranger", {"/battery_state": (BATTERY_STATE_TYPE, msgs)})
    rec = read_recording_bag(bag)
    np.testing.assert_allclose(rec.current_a, 3.0)  # negative in the message = discharge = positive inside
    np.testing.assert_allclose(rec.temperature_k, 21.5 + 273.15)
    assert rec.time_s[0] == pytest.approx(start / 1e9)  # epoch seconds without our time keys
    assert rec.metadata == {}


def test_battery_state_header_stamp_is_used_and_zero_stamp_falls_back_to_receive_time(tmp_path: Path) -> None:
    start = 1_760_000_000 * 10**9
    msgs = [(start + k * 10**8 + 5_000_000, battery_state_msg(start + k * 10**8, 48.0, -1.0)) for k in range(10)]
    msgs.append((start + 2 * 10**9, battery_state_msg(0, 47.9, -1.0)))
    rec = read_recording_bag(write_raw_bag(tmp_path / "stamps", {"/battery_state": (BATTERY_STATE_TYPE, msgs)}))
    assert rec.time_s[0] == pytest.approx(start / 1e9, abs=1e-6)
    assert rec.time_s[-1] == pytest.approx((start + 2 * 10**9) / 1e9, abs=1e-6)
    assert rec.temperature_k is None  # NaN = not measured


def test_repeated_stamps_keep_the_last_message(tmp_path: Path) -> None:
    start = 1_760_000_000 * 10**9
    msgs = [(start + k, battery_state_msg(start + (k // 2) * 10**8, 48.0 - k, -1.0)) for k in range(6)]
    rec = read_recording_bag(write_raw_bag(tmp_path / "dups", {"/battery_state": (BATTERY_STATE_TYPE, msgs)}))
    np.testing.assert_array_equal(rec.voltage_v, [47.0, 45.0, 43.0])
    assert rec.metadata["dropped_duplicate_stamps"] == 3


def test_nan_voltage_in_a_message_is_reported_or_dropped(tmp_path: Path) -> None:
    start = 1_760_000_000 * 10**9
    msgs = [(start + k * 10**8, battery_state_msg(start + k * 10**8, float("nan") if k == 4 else 48.0, -1.0)) for k in range(10)]
    bag = write_raw_bag(tmp_path / "nan", {"/battery_state": (BATTERY_STATE_TYPE, msgs)})
    with pytest.raises(InputDataError, match=r"/battery_state: sample 4 .*drop_nan=True"):
        read_recording_bag(bag)
    rec = read_recording_bag(bag, drop_nan=True)
    assert len(rec.time_s) == 9 and rec.metadata["dropped_nan_samples"] == 1


def test_relay_float32_topics_are_paired_by_nearest_receive_time(tmp_path: Path) -> None:
    start = 1_760_000_000 * 10**9
    period = 10**8
    volts = [(start + k * period, float_msg(14.0 - 0.001 * k, "std_msgs/msg/Float32")) for k in range(100)]
    # current arrives 3 ms after its voltage; none between samples 40 and 59 (Wi-Fi drop-out)
    amps = [(start + k * period + 3_000_000, float_msg(2.0 + 0.01 * k, "std_msgs/msg/Float32")) for k in range(100) if not 40 <= k < 60]
    temp_cls, header_cls = TS.types["sensor_msgs/msg/Temperature"], TS.types["std_msgs/msg/Header"]
    temps = [
        (start + k * 10**9, temp_cls(header=header_cls(stamp=TS.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""), temperature=30.0 + k, variance=0.0))
        for k in range(10)
    ]
    bag = write_raw_bag(
        tmp_path / "esp32",
        {
            "/battery/voltage": ("std_msgs/msg/Float32", volts),
            "/battery/current": ("std_msgs/msg/Float32", amps),
            "/battery/temperature": ("sensor_msgs/msg/Temperature", temps),
        },
    )
    rec = read_recording_bag(bag)
    kept = [k for k in range(100) if not 45 <= k <= 55]  # voltage samples with a current sample within 0.5 s
    nearest = [k if not 40 <= k < 60 else (39 if k < 50 else 60) for k in kept]
    np.testing.assert_allclose(rec.current_a, np.float32([2.0 + 0.01 * k for k in nearest]), rtol=1e-6)
    np.testing.assert_allclose(rec.voltage_v, np.float32([14.0 - 0.001 * k for k in kept]), rtol=1e-6)
    assert rec.metadata["relay_unpaired_samples"] == 11
    np.testing.assert_allclose(rec.temperature_k[:6] - 273.15, [30.0] * 6)  # nearest (receive time, not header stamp)


# ---------------------------------------------------------------------------
# topic errors
# ---------------------------------------------------------------------------


def test_bag_without_supported_topics_lists_what_it_has(tmp_path: Path) -> None:
    bag = write_raw_bag(tmp_path / "odom", {"/chatter": ("std_msgs/msg/String", [(1, TS.types["std_msgs/msg/String"](data="hi"))])})
    msg = bag_error(bag, "no supported battery topics")
    assert "/chatter [std_msgs/msg/String] x1" in msg
    info = bag_info(bag)
    assert info["summary"] is None and "no supported" in info["summary_error"]


def test_requested_topic_of_unsupported_type_lists_topics_and_types(tmp_path: Path, relay_bag: Path) -> None:
    bag = write_raw_bag(tmp_path / "mixed", {
        "/chatter": ("std_msgs/msg/String", [(1, TS.types["std_msgs/msg/String"](data="hi"))]),
        "/battery_state": (BATTERY_STATE_TYPE, [(2, battery_state_msg(2, 48.0, -1.0))]),
    })
    msg = bag_error(bag, "topic '/chatter' has type std_msgs/msg/String", topic="/chatter")
    assert "/battery_state [sensor_msgs/msg/BatteryState] x1" in msg
    bag_error(relay_bag, "topic '/battery/temperature' has type sensor_msgs/msg/Temperature", topic="/battery/temperature")


def test_requested_topic_that_does_not_exist_lists_topics(relay_bag: Path) -> None:
    msg = bag_error(relay_bag, "topic '/battery_state' is not in the bag", topic="/battery_state")
    assert "/battery/voltage [std_msgs/msg/Float64]" in msg


def test_relay_topics_can_be_selected_by_prefix_or_member(relay_bag: Path) -> None:
    a = read_recording_bag(relay_bag, topic="/battery")
    b = read_recording_bag(relay_bag, topic="/battery/current")
    assert np.array_equal(a.current_a, b.current_a)


def test_several_battery_state_topics_need_a_choice(tmp_path: Path) -> None:
    msgs = [(k, battery_state_msg(k, 48.0, -1.0)) for k in range(1, 4)]
    bag = write_raw_bag(tmp_path / "two", {"/a/battery": (BATTERY_STATE_TYPE, msgs), "/b/battery": (BATTERY_STATE_TYPE, msgs)})
    bag_error(bag, "pass topic=")
    assert len(read_recording_bag(bag, topic="/b/battery").time_s) == 3


def test_flipped_relay_current_is_caught_when_a_discharge_is_expected(tmp_path: Path, recording: Recording) -> None:
    flipped = Recording(recording.time_s, recording.voltage_v, -recording.current_a, recording.temperature_k)
    bag = write_recording_bag(flipped, tmp_path / "reversed_ina260", style="relay")
    with pytest.raises(InputDataError, match="current_A > 0 must mean DISCHARGE"):
        read_recording_bag(bag, expect_discharge=True)
    read_recording_bag(bag)  # off by default: robots also charge


# ---------------------------------------------------------------------------
# corrupt, truncated and missing bags
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("fraction", [0.0005, 0.1, 0.5, 0.9, 0.999])
def test_truncated_mcap_is_reported_as_corrupt(relay_bag: Path, fraction: float) -> None:
    mcap = the_mcap(relay_bag)
    data = mcap.read_bytes()
    mcap.write_bytes(data[: max(1, int(len(data) * fraction))])
    bag_error(relay_bag, "corrupt or truncated")
    bag_error(mcap, "corrupt or truncated")
    with pytest.raises(BagError, match="corrupt or truncated"):
        bag_info(relay_bag)


def test_empty_mcap_file_is_reported_as_corrupt(relay_bag: Path) -> None:
    the_mcap(relay_bag).write_bytes(b"")
    bag_error(the_mcap(relay_bag), "empty")
    bag_error(relay_bag, "corrupt or truncated")


def test_garbage_mcap_is_reported_as_corrupt(tmp_path: Path) -> None:
    path = tmp_path / "noise.mcap"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    bag_error(path, "corrupt or truncated")


def test_flipped_bytes_in_a_message_are_caught_by_the_stored_checksum(tmp_path: Path, recording: Recording) -> None:
    bag = write_recording_bag(recording, tmp_path / "flip", style="relay")
    mcap = the_mcap(bag)
    data = bytearray(mcap.read_bytes())
    needle = struct.pack("<d", float(recording.voltage_v[200]))
    pos = data.find(needle)
    assert pos > 0
    data[pos:pos + 8] = struct.pack("<d", float(recording.voltage_v[200]) + 1.0)  # still a valid, plausible value
    mcap.write_bytes(bytes(data))
    bag_error(bag, "SHA-256")


def test_unreadable_metadata_yaml_is_reported(relay_bag: Path) -> None:
    (relay_bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    bag_error(relay_bag, "corrupt")


def test_metadata_yaml_pointing_to_missing_storage_is_reported(relay_bag: Path) -> None:
    the_mcap(relay_bag).unlink()
    bag_error(relay_bag, "missing")


def test_directory_without_metadata_yaml_reads_its_single_mcap(relay_bag: Path, recording: Recording) -> None:
    (relay_bag / "metadata.yaml").unlink()  # a recorder killed before writing it
    assert np.array_equal(read_recording_bag(relay_bag).voltage_v, recording.voltage_v)


def test_missing_path_and_non_bag_paths_are_reported(tmp_path: Path) -> None:
    bag_error(tmp_path / "nothing", "not found")
    (tmp_path / "empty_dir").mkdir()
    bag_error(tmp_path / "empty_dir", "not a rosbag2 directory")
    (tmp_path / "x.txt").write_text("hello")
    bag_error(tmp_path / "x.txt", "not a bag")


# ---------------------------------------------------------------------------
# writing rules
# ---------------------------------------------------------------------------


def test_existing_bag_is_only_replaced_with_overwrite(tmp_path: Path, relay_bag: Path) -> None:
    rec = make_recording(5, n=50)
    with pytest.raises(BagError, match="already exists"):
        write_recording_bag(rec, relay_bag)
    write_recording_bag(rec, relay_bag, overwrite=True)
    assert len(read_recording_bag(relay_bag).time_s) == 50
    (tmp_path / "precious").mkdir()
    (tmp_path / "precious" / "notes.txt").write_text("keep me")
    with pytest.raises(BagError, match="not a bag directory"):
        write_recording_bag(rec, tmp_path / "precious", overwrite=True)
    assert (tmp_path / "precious" / "notes.txt").exists()


def test_bad_metadata_and_options_are_rejected_without_leaving_a_bag(tmp_path: Path, recording: Recording) -> None:
    with pytest.raises(BagError, match="'battery_predictor.style'.*reserved"):
        write_recording_bag(recording, tmp_path / "a", metadata={"battery_predictor.style": "x"})
    with pytest.raises(BagError, match="'blob'.*JSON"):
        write_recording_bag(recording, tmp_path / "b", metadata={"blob": object()})
    with pytest.raises(BagError, match="unknown bag style 'bms'"):
        write_recording_bag(recording, tmp_path / "c", style="bms")
    with pytest.raises(BagError, match="not a .mcap file name"):
        write_recording_bag(recording, tmp_path / "d.mcap")
    bad = Recording(recording.time_s[::-1].copy(), recording.voltage_v, recording.current_a)
    with pytest.raises(BagError, match="strictly increasing"):
        write_recording_bag(bad, tmp_path / "e")
    assert not any(tmp_path.iterdir())


def test_numpy_values_in_metadata_are_stored_as_json(tmp_path: Path, recording: Recording) -> None:
    bag = write_recording_bag(recording, tmp_path / "np", metadata={"seed": np.int64(7), "t": np.array([1.5, 2.0])})
    assert read_recording_bag(bag).metadata == {"seed": 7, "t": [1.5, 2.0]}


# ---------------------------------------------------------------------------
# bag_info
# ---------------------------------------------------------------------------


def test_bag_info_reports_topics_span_metadata_and_summary(relay_bag: Path, recording: Recording) -> None:
    info = bag_info(relay_bag)
    assert info["topics"] == [
        {"name": "/battery/current", "type": "std_msgs/msg/Float64", "count": 400},
        {"name": "/battery/temperature", "type": "sensor_msgs/msg/Temperature", "count": 400},
        {"name": "/battery/voltage", "type": "std_msgs/msg/Float64", "count": 400},
    ]
    assert info["message_count"] == 1200
    assert info["start"] == "2024-01-01T00:00:00.100000Z"  # time_s[0] = 0.1 s
    assert info["metadata"] == {"pack_id": "temi-1"}
    assert info["style"] == "relay" and info["battery_topic"] == "/battery"
    s = info["summary"]
    assert s["samples"] == 400
    assert s["charge_drawn_ah"] == pytest.approx(recording.charge_drawn_ah(), rel=1e-12)
    assert s["min_voltage_v"] == recording.voltage_v.min() and s["max_voltage_v"] == recording.voltage_v.max()
    assert s["mean_current_a"] == pytest.approx(recording.charge_drawn_ah() * 3600 / recording.duration_s)
    json.dumps(info)  # JSON-serialisable


# ---------------------------------------------------------------------------
# loader and conversions
# ---------------------------------------------------------------------------


def test_load_recording_dispatches_on_path_kind(tmp_path: Path, relay_bag: Path, recording: Recording) -> None:
    csv_path = save_csv(recording, tmp_path / "rec.csv")
    assert np.array_equal(load_recording(csv_path).voltage_v, recording.voltage_v)
    assert np.array_equal(load_recording(relay_bag).voltage_v, recording.voltage_v)
    assert np.array_equal(load_recording(the_mcap(relay_bag)).voltage_v, recording.voltage_v)
    (tmp_path / "rec.parquet").write_bytes(b"PAR1")
    with pytest.raises(InputDataError, match="unknown recording format"):
        load_recording(tmp_path / "rec.parquet")
    (tmp_path / "folder").mkdir()
    with pytest.raises(InputDataError, match="unknown recording format"):
        load_recording(tmp_path / "folder")
    with pytest.raises(InputDataError, match="not found"):
        load_recording(tmp_path / "gone.txt")
    with pytest.raises(BagError, match="not found"):
        load_recording(tmp_path / "gone.mcap")


def test_csv_to_bag_and_back_preserves_the_data(tmp_path: Path, recording: Recording) -> None:
    csv_path = save_csv(recording, tmp_path / "in.csv")
    for style in ("battery_state", "relay"):
        bag = csv_to_bag(csv_path, tmp_path / f"bag_{style}", style, metadata={"pack_id": "P7"})
        meta = read_recording_bag(bag).metadata
        assert meta["source_csv"] == "in.csv" and meta["pack_id"] == "P7"
        out = bag_to_csv(bag, tmp_path / f"out_{style}.csv")
        back = load_csv(out)
        assert np.array_equal(back.time_s, recording.time_s)
        if style == "relay":
            assert np.array_equal(back.voltage_v, recording.voltage_v)
            assert np.array_equal(back.current_a, recording.current_a)
        else:
            assert_float32_equal(back.voltage_v, recording.voltage_v)
            assert_float32_equal(back.current_a, recording.current_a)


# ---------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------


def test_cli_bag_info_prints_text_and_json(relay_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bag", "info", str(relay_bag)]) == 0
    out = capsys.readouterr().out
    assert "/battery/voltage" in out and "charge drawn" in out and "pack_id" in out
    assert main(["bag", "info", str(relay_bag), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["summary"]["samples"] == 400


def test_cli_from_csv_and_to_csv_round_trip(tmp_path: Path, recording: Recording, capsys: pytest.CaptureFixture[str]) -> None:
    csv_path = save_csv(recording, tmp_path / "in.csv")
    bag = tmp_path / "bag"
    assert main(["bag", "from-csv", str(csv_path), str(bag), "--style", "relay", "--meta", "pack_id=temi-2", "--meta", "seed=3"]) == 0
    assert read_recording_bag(bag).metadata["seed"] == 3
    assert main(["bag", "to-csv", str(bag), str(tmp_path / "out.csv")]) == 0
    assert np.array_equal(load_csv(tmp_path / "out.csv").voltage_v, recording.voltage_v)
    capsys.readouterr()
    assert main(["bag", "to-csv", str(bag), str(tmp_path / "out.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already exists" in err


def test_cli_errors_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("time_s,voltage_V\n0,3.7\n")
    assert main(["bag", "from-csv", str(bad_csv), str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'current_A'" in err and str(bad_csv) in err
    assert main(["bag", "info", str(tmp_path / "missing")]) == 2
    assert "not found" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def test_cli_subprocess_reports_a_corrupt_bag_in_one_line(relay_bag: Path) -> None:
    mcap = the_mcap(relay_bag)
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run(
        [sys.executable, "-m", "battery_predictor.cli.main", "bag", "info", str(relay_bag)],
        capture_output=True, text=True, timeout=120, cwd=REPO, env=env, check=False,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr and str(relay_bag) in lines[0] and "corrupt or truncated" in lines[0]


def test_all_bag_errors_are_battery_predictor_errors() -> None:
    assert issubclass(BagError, BatteryPredictorError) and issubclass(InputDataError, BatteryPredictorError)
