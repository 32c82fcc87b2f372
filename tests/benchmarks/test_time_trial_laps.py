"""The time-trial benchmark: model files alone against the teacher, race by race."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator
from types import ModuleType

import pytest

from tests.benchmarks.scripts import BENCHMARKS, benchmark_script

ROOT = BENCHMARKS.parent
SAMPLE = ROOT / "league" / "demo_models" / "sample-time-trial.zip"


@pytest.fixture(scope="module")
def laps() -> Iterator[ModuleType]:
    """``benchmarks/time_trial_laps.py`` as a module."""
    with benchmark_script("time_trial_laps") as module:
        yield module


def test_seeds_are_a_range_or_a_list(laps: ModuleType) -> None:
    assert laps.seed_range("10-13") == [10, 11, 12, 13]
    assert laps.seed_range("0,3,5") == [0, 3, 5]
    with pytest.raises(argparse.ArgumentTypeError, match="backwards"):
        laps.seed_range("5-2")


def test_a_driver_is_compared_with_the_teacher_on_the_races_both_finished(
    laps: ModuleType,
) -> None:
    teacher = {0: 7.0, 1: 7.2, 2: None, 3: 7.1}
    driver = {0: 6.9, 1: 7.4, 2: 7.0, 3: None}  # seed 2: the teacher did not finish
    faster, difference = laps.against(driver, teacher)
    assert faster == "1/2"
    assert difference.startswith("+0.050 ± 0.150")
    assert laps.against({0: None}, teacher) == ["-", "-"]


def test_a_model_and_the_teacher_lap_a_track() -> None:
    command = [sys.executable, str(BENCHMARKS / "time_trial_laps.py"), "--model", str(SAMPLE)]
    command += ["--tracks", "slipstream_speedway", "--seeds", "0", "--laps", "1", "--no-record"]
    out = subprocess.run(command, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    rows = [line for line in out.splitlines() if "slipstream_speedway" in line]
    assert len(rows) == 2 and "the teacher" in rows[0] and SAMPLE.name in rows[1]
    assert all("1/1" in row for row in rows)  # both finished their lap
