"""DeepRacer's episode rules for one car: progress, laps, incidents, penalties, resets.

Pure bookkeeping (no physics): the env measures each car every control step and asks
:class:`RuleBook` what happened, in the spec's order — lap complete, immobilised, off
track, crashed, reversed, time up. In ``training`` mode the first incident ends the
car's episode; in ``race`` mode the car is frozen for the penalty and then respawned.
:meth:`RuleBook.at_fault` says which party of a contact caused it (the crash rule).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from arena.car_spec import DEFAULT_CAR
from arena.config import Mode, Penalties
from tracks.track import Track

EpisodeStatus = Literal[
    "prepare",
    "in_progress",
    "off_track",
    "crashed",
    "immobilized",
    "reversed",
    "lap_complete",
    "pause",
    "park",
    "time_up",
]
INCIDENTS = ("immobilized", "off_track", "crashed", "reversed")
STUCK_STEPS = 15
IMMOBILE_METRES = 0.0003
# Contacts (docs/arena.md, "Contacts and fault"): two parties whose arc lengths differ by
# less than half a car length are side by side; one of them steered into the other when
# it moved this much further across the track towards the other in the step (0.15 m/s at
# 15 Hz); a car released from a penalty is rejoining for this long.
SIDE_BY_SIDE_M = 0.5 * DEFAULT_CAR.length
SWERVE_M = 0.01
REJOIN_S = 1.0


@dataclass
class CarRecord:
    """The racing state of one car (mutable; owned by the env)."""

    start_arc: float
    last_arc: float
    start_time: float
    distance: float = 0.0
    lap_start_distance: float = 0.0
    lap_start_time: float = 0.0
    lap_times: list[float] = field(default_factory=list)
    steps: int = 0
    off_track_count: int = 0
    crash_count: int = 0
    reset_count: int = 0
    penalty_seconds: float = 0.0
    immobile_steps: int = 0
    reversing_steps: int = 0
    frozen_until: float | None = None
    status: EpisodeStatus = "prepare"
    done: bool = False
    truncated: bool = False
    finished: bool = False
    step_delta: float = 0.0

    @property
    def laps(self) -> int:
        """Completed laps."""
        return len(self.lap_times)

    @property
    def frozen(self) -> bool:
        """Serving a penalty (race mode)."""
        return self.frozen_until is not None


@dataclass(frozen=True)
class Measurement:
    """What the env measured for one car after a control step."""

    arc: float
    moved: float
    any_wheel_on_track: bool
    crashed: bool


@dataclass(frozen=True)
class ContactParty:
    """One party of a contact, as the fault rules see it.

    ``toward`` is how far it moved across the track towards the other party in the step
    (metres, negative when away); ``held`` is a car frozen in place serving a penalty;
    ``rejoining`` a car released from a penalty less than ``REJOIN_S`` ago.
    """

    kind: Literal["car", "bot", "box"]
    arc: float
    toward: float = 0.0
    held: bool = False
    rejoining: bool = False


class RuleBook:
    """Applies the episode rules for one race or training episode on ``track``."""

    def __init__(
        self,
        track: Track,
        mode: Mode,
        laps: int,
        penalties: Penalties,
        max_resets: int | None,
        time_limit_s: float,
    ) -> None:
        self.track = track
        self.mode = mode
        self.laps = laps if mode == "race" else 1
        self.penalties = penalties
        self.max_resets = max_resets
        self.time_limit_s = time_limit_s

    def start(self, arc: float, now: float) -> CarRecord:
        """A fresh record for a car starting at arc length ``arc``."""
        return CarRecord(
            start_arc=arc, last_arc=arc, start_time=now, lap_start_time=now, status="prepare"
        )

    def progress(self, rec: CarRecord) -> float:
        """Percent of the current lap done, 0 to 100."""
        pct = 100.0 * (rec.distance - rec.lap_start_distance) / self.track.length
        return min(max(pct, 0.0), 100.0)

    def _advance(self, rec: CarRecord, arc: float) -> float:
        delta = self.track.arc_delta(rec.last_arc, arc)
        rec.last_arc = arc
        rec.distance += delta
        return delta

    def update(self, rec: CarRecord, m: Measurement, now: float) -> EpisodeStatus:
        """Apply one step's measurement at simulated time ``now``; returns the new status."""
        if rec.done:
            return rec.status
        rec.steps += 1
        if rec.frozen:
            return self._serve_penalty(rec, now)
        delta = self._advance(rec, m.arc)
        rec.step_delta = delta
        rec.immobile_steps = rec.immobile_steps + 1 if m.moved <= IMMOBILE_METRES else 0
        rec.reversing_steps = rec.reversing_steps + 1 if delta < -1e-6 else 0

        lap_done = rec.distance - rec.lap_start_distance >= self.track.length
        if lap_done:
            self._complete_lap(rec, now)
            if rec.done:
                return rec.status
        elif rec.immobile_steps >= STUCK_STEPS:
            return self._incident(rec, "immobilized", now)
        elif not m.any_wheel_on_track:
            return self._incident(rec, "off_track", now)
        elif m.crashed:
            return self._incident(rec, "crashed", now)
        elif rec.reversing_steps >= STUCK_STEPS:
            return self._incident(rec, "reversed", now)
        if now - rec.start_time >= self.time_limit_s - 1e-9:
            rec.status, rec.done, rec.truncated = "time_up", True, True
            return rec.status
        rec.status = "lap_complete" if lap_done else "in_progress"
        return rec.status

    def _complete_lap(self, rec: CarRecord, now: float) -> None:
        rec.lap_times.append(now - rec.lap_start_time)
        rec.lap_start_time = now
        rec.lap_start_distance += self.track.length
        rec.status = "lap_complete"
        if rec.laps >= self.laps:
            rec.done = rec.finished = True

    def _incident(self, rec: CarRecord, kind: EpisodeStatus, now: float) -> EpisodeStatus:
        rec.status = kind
        if kind == "off_track":
            rec.off_track_count += 1
        elif kind == "crashed":
            rec.crash_count += 1
        if self.mode == "training":
            rec.done = True
            return kind
        penalty = {
            "off_track": self.penalties.off_track_s,
            "crashed": self.penalties.crash_s,
        }.get(kind, self.penalties.reset_s)
        rec.penalty_seconds += penalty
        rec.reset_count += 1
        rec.immobile_steps = rec.reversing_steps = 0
        if self.max_resets is not None and rec.reset_count > self.max_resets:
            rec.done = True
            return kind
        rec.frozen_until = now + penalty
        return kind

    def _serve_penalty(self, rec: CarRecord, now: float) -> EpisodeStatus:
        if now - rec.start_time >= self.time_limit_s - 1e-9:
            rec.status, rec.done, rec.truncated = "time_up", True, True
            return rec.status
        if rec.frozen_until is not None and now >= rec.frozen_until - 1e-9:
            rec.frozen_until = None
            rec.status = "in_progress"
            return "in_progress"
        rec.status = "pause"
        return "pause"

    def at_fault(self, me: ContactParty, other: ContactParty) -> bool:
        """Whether ``me`` caused its contact with ``other``; never both parties.

        In order: a held car, a bot or a box never is; a car hitting a box or a held car
        is; a car rejoining after a penalty is, against one already racing; side by side
        (arc lengths within ``SIDE_BY_SIDE_M``) the one that steered into the other
        (moved ``SWERVE_M`` more towards it), else neither; otherwise the one behind.
        """
        if me.kind != "car" or me.held:
            return False
        if other.kind == "box" or other.held:
            return True
        if me.rejoining != other.rejoining:
            return me.rejoining
        gap = self.track.arc_delta(me.arc, other.arc)
        if abs(gap) < SIDE_BY_SIDE_M:
            return me.toward - other.toward > SWERVE_M
        return gap > 0

    def respawned(self, rec: CarRecord, arc: float) -> None:
        """Account for a car moved to arc length ``arc`` (a respawn, maybe behind)."""
        self._advance(rec, arc)
