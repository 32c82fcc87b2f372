"""Racing metrics of a multi-car race: overtakes, contacts and their fault, laps led.

Pure bookkeeping, fed once per control step with every racing car's :class:`CarStep`
(:func:`arena.race.run_race` builds them from the env's step ``info``):

- **position**: a car's place along the track is its race distance plus its grid offset
  (``start_offsets``: metres from the front of the grid, negative behind it), so that
  every car is measured from the same line and a car one lap up stays ahead.
- **overtake**: car A moves from behind car B to more than :data:`PASS_MARGIN_M` ahead
  of it while both have been racing on track (status ``in_progress`` or
  ``lap_complete``) for :data:`SETTLED_STEPS` steps in a row. A pass made while B serves
  a penalty, or through a respawn of either car, changes who is ahead without counting
  (a car is respawned in the step after its incident, and a car released from a penalty
  may be moved to a free spot in the step after its release: both moves fall within
  those steps).
- **contact**: an incident between a car and another car, bot or box lasts as long as
  they touch on consecutive steps; each car at fault in it counts one at-fault collision
  (not one per touching step).
- **laps led**: lap ``k`` is led by the first car to complete it (in a race where every
  car covers the same distance from its own start, that car leads at the line);
  completions in the same step go to the car furthest past the line.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

RACING_STATUSES = frozenset({"in_progress", "lap_complete"})
PASS_MARGIN_M = 0.05
SETTLED_STEPS = 3
EventKind = Literal["overtake", "contact"]


@dataclass(frozen=True)
class Contact:
    """A contact of one car this step: ``other`` is a car name, ``"bot<i>"`` or ``"box<i>"``."""

    other: str
    at_fault: bool


@dataclass(frozen=True)
class CarStep:
    """What the tracker needs of one racing car after a control step."""

    distance: float
    laps: int
    status: str
    contacts: Sequence[Contact] = ()

    @classmethod
    def from_info(cls, info: Mapping[str, Any]) -> CarStep:
        """The step of a car from the env's ``info`` dict."""
        return cls(
            distance=float(info["distance"]),
            laps=int(info["laps"]),
            status=str(info["episode_status"]),
            contacts=tuple(Contact(str(c["other"]), bool(c["at_fault"])) for c in info["contacts"]),
        )


@dataclass(frozen=True)
class RaceEvent:
    """An overtake (``car`` passed ``other``) or a contact (``car`` touched ``other``;
    ``at_fault`` says whether ``car`` was judged at fault) at simulated time ``t``."""

    t: float
    kind: EventKind
    car: str
    other: str
    at_fault: bool

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: ``{"t", "kind", "car", "other", "at_fault"}``."""
        return {
            "t": self.t,
            "kind": self.kind,
            "car": self.car,
            "other": self.other,
            "at_fault": self.at_fault,
        }


@dataclass
class CarMetrics:
    """One car's racing metrics so far."""

    overtakes: int = 0
    times_overtaken: int = 0
    at_fault_collisions: int = 0
    laps_led: int = 0


@dataclass
class _Incident:
    """A contact going on between two objects, and who has been counted at fault in it."""

    counted: set[str] = field(default_factory=set)


class RacingMetrics:
    """Counts overtakes, at-fault collisions and laps led, and lists the race's events.

    Args:
        start_offsets: every car's grid offset, metres along the track from the front of
            the grid (0 for the leading slot, negative behind it). Its order is the grid
            order, which breaks ties between cars level at the start.
    """

    def __init__(self, start_offsets: Mapping[str, float]) -> None:
        self._offsets = dict(start_offsets)
        self.cars = {name: CarMetrics() for name in self._offsets}
        self.events: list[RaceEvent] = []
        self._ahead: dict[tuple[str, str], bool] = {}
        self._streak = dict.fromkeys(self._offsets, 0)
        self._laps_done: dict[int, str] = {}
        self._incidents: dict[frozenset[str], _Incident] = {}
        grid = list(self._offsets)
        for i, a in enumerate(grid):
            for b in grid[i + 1 :]:
                self._ahead[(a, b)] = self._offsets[a] >= self._offsets[b]

    def update(self, t: float, steps: Mapping[str, CarStep]) -> None:
        """Account for one control step at simulated time ``t``; ``steps`` holds every car
        still racing (cars that have finished or dropped out are left out)."""
        for name in self._streak:
            racing = name in steps and steps[name].status in RACING_STATUSES
            self._streak[name] = self._streak[name] + 1 if racing else 0
        settled = {name for name, streak in self._streak.items() if streak >= SETTLED_STEPS}
        self._overtakes(t, steps, settled)
        self._contacts(t, steps)
        self._laps(steps)

    def _overtakes(self, t: float, steps: Mapping[str, CarStep], eligible: set[str]) -> None:
        position = {name: step.distance + self._offsets[name] for name, step in steps.items()}
        for (a, b), a_ahead in self._ahead.items():
            if a not in position or b not in position:
                continue
            lead = position[a] - position[b]
            if a_ahead and lead < -PASS_MARGIN_M:
                passer, passed = b, a
            elif not a_ahead and lead > PASS_MARGIN_M:
                passer, passed = a, b
            else:
                continue
            self._ahead[(a, b)] = not a_ahead
            if passer in eligible and passed in eligible:
                self.cars[passer].overtakes += 1
                self.cars[passed].times_overtaken += 1
                self.events.append(RaceEvent(t, "overtake", passer, passed, False))

    def _contacts(self, t: float, steps: Mapping[str, CarStep]) -> None:
        touching: dict[frozenset[str], list[tuple[str, Contact]]] = {}
        for name, step in steps.items():
            for contact in step.contacts:
                touching.setdefault(frozenset((name, contact.other)), []).append((name, contact))
        incidents = {}
        for pair, reports in touching.items():
            incident = self._incidents.get(pair)
            is_new = incident is None
            incident = incident or _Incident()
            incidents[pair] = incident
            at_fault = [
                (car, c) for car, c in reports if c.at_fault and car not in incident.counted
            ]
            for car, contact in at_fault:
                incident.counted.add(car)
                self.cars[car].at_fault_collisions += 1
                self.events.append(RaceEvent(t, "contact", car, contact.other, True))
            if is_new and not at_fault:
                car, contact = reports[0]
                self.events.append(RaceEvent(t, "contact", car, contact.other, False))
        self._incidents = incidents

    def _laps(self, steps: Mapping[str, CarStep]) -> None:
        completed: dict[int, list[str]] = {}
        for name, step in steps.items():
            for lap in range(1, step.laps + 1):
                if lap not in self._laps_done:
                    completed.setdefault(lap, []).append(name)
        for lap, names in completed.items():
            leader = max(names, key=lambda n: steps[n].distance)
            self._laps_done[lap] = leader
            self.cars[leader].laps_led += 1
