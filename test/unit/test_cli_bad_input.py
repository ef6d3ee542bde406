"""What a new user meets: impossible params, late failures, hints and messages, as the CLI prints them.

Every error here is one line on stderr, exit code 2, no traceback, and names the flag, file or key.
"""

from __future__ import annotations

import argparse
import io
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from battery_predictor.cli.cmd_demo import output_dir
from battery_predictor.cli.common import progress_bar, progress_wanted
from battery_predictor.cli.main import build_parser, flag_map
from battery_predictor.errors import InputDataError, cli_flags, option_hint
from battery_predictor.io.bags import read_recording_bag, write_recording_bag
from battery_predictor.io.csv_io import save_csv

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")
TEMI = str(REPO / "params" / "temi.yaml")
RANGER = str(REPO / "params" / "ranger_mini.yaml")
TEMI_BAG = str(REPO / "bags" / "temi_dynamic_pack1")
#: Python option names the input readers put into their hints (errors.option_hint).
HINTED_OPTIONS = {"drop_nan": True, "expect_discharge": False, "duplicate_times": "keep_last", "overwrite": True,
                  "topic": None}


def _run(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([CLI, *args], capture_output=True, text=True, timeout=600, cwd=cwd)


def _one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _params_with(tmp_path: Path, mutate, base: str = TEMI) -> str:
    data = yaml.safe_load(Path(base).read_text())
    mutate(data)
    path = tmp_path / "changed.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


@pytest.fixture(scope="module")
def short_csv(tmp_path_factory) -> Path:
    """The first ~30 min of the bundled temi recording as CSV."""
    rec = read_recording_bag(TEMI_BAG)
    keep = rec.time_s <= 1800.0
    from battery_predictor.recording import Recording

    short = Recording(time_s=rec.time_s[keep], voltage_v=rec.voltage_v[keep], current_a=rec.current_a[keep],
                      temperature_k=None if rec.temperature_k is None else rec.temperature_k[keep], source="short")
    return save_csv(short, tmp_path_factory.mktemp("data") / "short.csv")


def _csv(tmp_path: Path, body: str, name: str = "data.csv") -> str:
    path = tmp_path / name
    path.write_text("time_s,voltage_V,current_A\n" + body)
    return str(path)


# ---------------------------------------------------------------- 1. physically impossible params
@pytest.mark.parametrize(("mutate", "fragments"), [
    (lambda d: d["pack"].update(nominal_capacity_ah=-14.70), ("pack.nominal_capacity_ah", "-14.7")),
    (lambda d: d["cell"]["manual"].update({"Nominal cell capacity [A.h]": -2.45}),
     ("Nominal cell capacity [A.h]", "must be > 0")),
])
def test_simulate_rejects_negative_capacities_before_simulating(tmp_path, short_csv, mutate, fragments):
    path = _params_with(tmp_path, mutate)
    _one_line_error(_run("simulate", "--params", path, "--data", str(short_csv)), "changed.yaml", *fragments)


def test_screen_rejects_a_series_count_the_pack_voltages_contradict(tmp_path):
    path = _params_with(tmp_path, lambda d: d["pack"].update(series=10000))
    _one_line_error(_run("screen", "--params", path), "pack.series", "10000")


def test_simulate_rejects_a_recording_of_another_pack(short_csv):
    _one_line_error(_run("simulate", "--params", RANGER, "--data", str(short_csv)),
                    "short.csv", "per cell", "not of this pack")


def test_run_rejects_a_monitor_range_that_misses_the_pack(tmp_path):
    nodes = yaml.safe_load((REPO / "params" / "ros" / "ranger_nodes.yaml").read_text())
    nodes["predictor"]["ros__parameters"]["params_file"] = "temi.yaml"
    path = tmp_path / "mixed_nodes.yaml"
    path.write_text(yaml.safe_dump(nodes))
    _one_line_error(_run("run", "--params", str(path)), "mixed_nodes.yaml", "37.5..58", "12..16.4")


def test_run_rejects_a_missing_pack_file_before_starting_the_nodes():
    _one_line_error(_run("run", "--params", "params/ros/temi_nodes.yaml", "--pack", "no_such_pack.yaml"),
                    "--pack", "no_such_pack.yaml", "not found")


# ------------------------------------------------------------------- 2. output paths checked first
def test_fit_out_directory_fails_before_the_fit(tmp_path, short_csv):
    _one_line_error(_run("fit", "--params", TEMI, "--data", str(short_csv), "--out", str(tmp_path)),
                    "--out", "is a directory")


def test_profile_plot_with_unknown_suffix_fails_before_the_profile(tmp_path):
    _one_line_error(_run("profile", "temi", "--points", "5", "--plot", str(tmp_path / "x.xyz")),
                    "--plot", "'.xyz'", ".png")
    assert not (tmp_path / "x.xyz").exists()


def test_simulate_plot_directory_fails_and_a_plot_file_is_reported(tmp_path, short_csv):
    _one_line_error(_run("simulate", "--params", TEMI, "--data", str(short_csv), "--plot", str(tmp_path)),
                    "--plot", "is a directory")
    proc = _run("simulate", "--params", TEMI, "--data", str(short_csv), "--plot", str(tmp_path / "fit.png"))
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {tmp_path / 'fit.png'}" in proc.stdout
    assert (tmp_path / "fit.png").stat().st_size > 0


# --------------------------------------------------------------------- 3. hints name real flags
def test_every_hint_names_a_flag_of_the_command_that_prints_it():
    def leaves(parser: argparse.ArgumentParser):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    if sub.get_default("func") is not None:
                        yield sub
                    yield from leaves(sub)

    checked = 0
    for parser in leaves(build_parser()):
        flags = {s for a in parser._actions for s in a.option_strings}
        with cli_flags(flag_map(parser)):
            for option, value in HINTED_OPTIONS.items():
                hint = option_hint(option, value, "to go on")
                assert "=" not in hint, (parser.prog, hint)
                if hint:
                    assert hint.split()[2] in flags, (parser.prog, hint)
                    checked += 1
    assert checked >= 8


def test_simulate_nan_row_hint_names_drop_nan_flag_that_works(tmp_path, short_csv):
    lines = Path(short_csv).read_text().splitlines()
    lines[5] = lines[5].split(",")[0] + ",nan," + ",".join(lines[5].split(",")[2:])
    path = tmp_path / "nan.csv"
    path.write_text("\n".join(lines) + "\n")
    message = _one_line_error(_run("simulate", "--params", TEMI, "--data", str(path)), "line 6", "use --drop-nan")
    assert "drop_nan" not in message
    assert _run("simulate", "--params", TEMI, "--data", str(path), "--drop-nan", "--json").returncode == 0


def test_wrong_current_sign_hint_names_no_sign_check(tmp_path):
    body = "".join(f"{t},{16.0 - 0.01 * t},{-2.0}\n" for t in range(50))
    message = _one_line_error(_run("fit", "--params", TEMI, "--data", _csv(tmp_path, body), "--out",
                                   str(tmp_path / "f.yaml")), "use --no-sign-check")
    assert "expect_discharge" not in message


def test_bag_to_csv_twice_hints_overwrite_and_writes_readable_file(tmp_path):
    out = tmp_path / "x.csv"
    assert _run("bag", "to-csv", TEMI_BAG, str(out)).returncode == 0
    assert out.stat().st_mode & 0o044 == 0o044  # group and others may read it, as any file the user writes
    message = _one_line_error(_run("bag", "to-csv", TEMI_BAG, str(out)), "already exists", "use --overwrite")
    assert "overwrite=" not in message


# ------------------------------------------------------------------------ 4. misleading messages
def test_params_directory_is_named_a_directory():
    _one_line_error(_run("screen", "--params", "params"), "params", "is a directory")


def test_repeated_timestamp_says_so_and_names_duplicate_times(tmp_path):
    # every command keeps the last row of a repeated time by default (cycler exports repeat the time at step
    # changes, as the LG M50 files of ../shared/data do); --duplicate-times error refuses them with the way out
    body = "0,16.0,2.0\n5,15.99,2.0\n5,15.98,2.0\n10,15.97,2.0\n"
    message = _one_line_error(_run("simulate", "--params", TEMI, "--data", _csv(tmp_path, body),
                                   "--duplicate-times", "error"),
                              "repeats the time of line 3", "use --duplicate-times keep_last")
    assert "not greater than" not in message


def test_data_commands_keep_the_last_row_of_a_repeated_time_by_default():
    from battery_predictor.cli.main import build_parser

    parser = build_parser()
    for argv in (["simulate", "--params", TEMI, "--data", "x.csv"],
                 ["fit", "--params", TEMI, "--data", "x.csv", "--out", "f.yaml"],
                 ["evaluate-runtime", "--params", TEMI, "--data", "x.csv"],
                 ["bag", "from-csv", "x.csv", "b"]):
        assert parser.parse_args(argv).duplicate_times == "keep_last", argv


# --------------------------------------------------------------------------- 5. progress on waits
class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_only_on_an_interactive_stderr_and_never_with_json():
    assert progress_wanted(argparse.Namespace(json=False), _Terminal())
    assert not progress_wanted(argparse.Namespace(json=True), _Terminal())
    assert not progress_wanted(argparse.Namespace(json=False, no_progress=True), _Terminal())
    assert not progress_wanted(argparse.Namespace(json=False), io.StringIO())


def test_progress_bar_appears_after_its_delay_and_stays_quiet_on_short_waits():
    short, long = _Terminal(), _Terminal()
    with progress_bar(5, "quick", "step", enabled=True, stream=short, delay_s=0.5) as update:
        for k in range(5):
            update(k + 1)
    with progress_bar(5, "slow", "step", enabled=True, stream=long, delay_s=0.2) as update:
        for k in range(5):
            time.sleep(0.1)
            update(k + 1)
    assert short.getvalue() == ""
    assert "slow" in long.getvalue() and re.search(r"\b[1-5]/5\b", long.getvalue())


# ------------------------------------------------------------------- 6. readable, portable artefacts
MACHINE_PATH = re.compile(r"[\"'` ]/(?:home|root|tmp|work|Users|var)/|sqlite:////")


def test_bag_info_is_a_short_readable_summary_and_json_keeps_everything():
    proc = _run("bag", "info", "bags/ranger_route_20kg_pack1")
    assert proc.returncode == 0, proc.stderr
    assert max(len(line) for line in proc.stdout.splitlines()) <= 100
    assert "--json prints them in full" in proc.stdout
    full = json.loads(_run("bag", "info", "bags/ranger_route_20kg_pack1", "--json").stdout)
    assert len(full["metadata"]["profile"]["curve_points"]["current_a"]) > 10


def test_shipped_bags_and_reports_hold_no_absolute_paths():
    files = [*REPO.glob("bags/*/metadata.yaml"), *REPO.glob("docs/**/*.json"), *REPO.glob("docs/**/*.md"),
             *REPO.glob("docs/**/*.yaml")]
    assert len(files) > 20
    offenders = [str(f.relative_to(REPO)) for f in files
                 if str(REPO) + "/" in f.read_text(errors="replace") or MACHINE_PATH.search(f.read_text(errors="replace"))]
    assert offenders == []


def test_written_bag_metadata_keeps_paths_relative_and_topics_as_they_are(tmp_path):
    rec = read_recording_bag(TEMI_BAG)
    meta = {"params": str(REPO / "params" / "temi.yaml"), "topic": "/battery_state",
            "files": {str(REPO / "bags" / "temi_dynamic_pack1"): 1}}
    write_recording_bag(rec, tmp_path / "bag", metadata=meta)
    stored = read_recording_bag(tmp_path / "bag").metadata
    assert stored["params"] == "params/temi.yaml"
    assert stored["topic"] == "/battery_state"
    assert stored["files"] == {"bags/temi_dynamic_pack1": 1}


# ----------------------------------------------------------------------------------- 7. small ones
def test_demo_without_out_removes_its_temporary_directory():
    with output_dir(None) as out:
        (out / "temi_outputs").mkdir()
        assert out.is_dir()
    assert not out.exists()


def test_demo_out_with_earlier_outputs_is_refused(tmp_path):
    (tmp_path / "temi_outputs").mkdir()
    with pytest.raises(InputDataError, match="temi_outputs exists"), output_dir(str(tmp_path)):
        pass


def test_screen_table_explains_its_runtime_column(monkeypatch, capsys):
    from battery_predictor.cli import cmd_screen
    from battery_predictor.fitting import screening

    row = screening.ScreeningRow("Electrode height [m]", 0.9, 12.0, 0.95, True)
    monkeypatch.setattr(screening, "screen", lambda *a, **k: [row])
    cmd_screen.run(argparse.Namespace(params=TEMI, simulator="fast", c_rate=None, all=False, json=False))
    out = capsys.readouterr().out
    assert "runtime %" in out.splitlines()[1]
    assert "runtime %: change of the time to the cut-off when the parameter is raised by 10 %" in out


def test_screen_shows_its_progress_on_a_terminal_and_nothing_when_piped(monkeypatch, capsys):
    """Item 5: the 42 s of ``screen`` showed nothing; now a bar counts the screened parameters."""
    from battery_predictor.cli import cmd_screen, common
    from battery_predictor.fitting import screening

    row = screening.ScreeningRow("Electrode height [m]", 0.9, 12.0, 0.95, True)

    def slow_screen(*_a, progress=None, **_k):
        for _ in range(4):
            time.sleep(0.15)
            progress(row)
        return [row]

    monkeypatch.setattr(screening, "screen", slow_screen)
    monkeypatch.setitem(common.progress_bar.__wrapped__.__kwdefaults__, "delay_s", 0.2)  # instead of 2 s
    args = argparse.Namespace(params=TEMI, simulator="fast", c_rate=None, all=False, json=False)
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    cmd_screen.run(args)
    assert re.search(r"screen:.*\b[1-4]/\d+ \[", terminal.getvalue()), terminal.getvalue()
    piped = io.StringIO()
    monkeypatch.setattr(sys, "stderr", piped)
    cmd_screen.run(args)
    assert piped.getvalue() == ""
    capsys.readouterr()


def test_replay_progress_counts_bag_minutes(monkeypatch):
    """Item 5: the demo's and replay's ~30 s replays move a bar in bag minutes (``bag_progress``)."""
    from types import SimpleNamespace

    from battery_predictor.cli import common

    monkeypatch.setitem(common.progress_bar.__wrapped__.__kwdefaults__, "delay_s", 0.0)
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    stream = SimpleNamespace(start_ns=0, end_ns=300 * 60 * 10**9)
    with common.bag_progress(stream, None, "replay", enabled=True) as update:
        on_step = common.bag_step(update, stream)
        for minute in (60, 150, 300):
            time.sleep(0.12)  # tqdm redraws at most every 0.1 s
            on_step(minute * 60 * 10**9)
    assert re.search(r"replay:.*\b150.0/300.0 \[", terminal.getvalue()), terminal.getvalue()
    assert "bag min" in terminal.getvalue()


def test_warnings_print_as_one_line_without_the_source_and_main_restores_the_format():
    from battery_predictor.cli import main as cli_main

    text = cli_main.one_line_warning(UserWarning("data.csv: starts above the cut-off"), UserWarning, "/x/y.py", 93,
                                     "req = replace(req)")
    assert text == "battery-predictor: warning: data.csv: starts above the cut-off\n"
    import warnings

    before = warnings.formatwarning
    assert cli_main.main(["simulate", "--params", "no_such_params.yaml", "--data", "no_such.csv"]) == 2
    assert warnings.formatwarning is before  # the command line's format does not leak into a caller


def test_replay_warns_when_the_bags_samples_are_further_apart_than_stale_after_s():
    # the LG M50 0.1C records are sampled every 20-60 s: through nodes with stale_after_s 15 / 30 s nearly every
    # answer was stale (7 of 1013 valid) while evaluate-runtime, which has no staleness, answered all 9 checkpoints
    from battery_predictor.cli.cmd_replay import sparse_input_warning

    sparse = np.arange(0.0, 3600.0, 60.0)
    message = sparse_input_warning("lg.bag", sparse, {"battery_monitor": 15.0, "predictor": 30.0})
    assert message is not None
    assert "60 s apart" in message and "battery_monitor stale_after_s 15 s" in message and "predictor" in message
    assert sparse_input_warning("lg.bag", sparse, {"battery_monitor": 90.0, "predictor": 90.0}) is None
    assert sparse_input_warning("dense.bag", np.arange(0.0, 600.0, 1.0), {"battery_monitor": 15.0}) is None
