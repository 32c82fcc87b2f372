"""Head-to-head records from placings (pure): wins, losses and attributable overtakes."""

from __future__ import annotations

from league.head_to_head import Placing, Tally, tally


def test_records_count_who_finished_ahead_and_duel_overtakes() -> None:
    placings = [
        # Race 1, a duel: model 2 wins after passing model 1 twice; model 1 passed once.
        Placing(1, 1, 2, 1),
        Placing(1, 2, 1, 2),
        # Race 2, three models: 3 ahead of 1 ahead of 2; overtakes here are not attributable.
        Placing(2, 2, 3, 5),
        Placing(2, 3, 1, 4),
        Placing(2, 1, 2, 3),
        # Race 3: model 1 against a bot: no pairing.
        Placing(3, None, 1, 0),
        Placing(3, 1, 2, 0),
    ]
    assert tally(placings) == [
        Tally(1, 2, races=2, wins=1, losses=1, overtakes=1, overtaken=2),
        Tally(1, 3, races=1, wins=0, losses=1, overtakes=0, overtaken=0),
        Tally(2, 3, races=1, wins=0, losses=1, overtakes=0, overtaken=0),
    ]


def test_no_shared_race_no_record() -> None:
    assert tally([Placing(1, 1, 1, 0), Placing(2, 2, 1, 0)]) == []
