"""``RUN/checkpoints/last.pt``: written whole, read back with ``weights_only``."""

from __future__ import annotations

import torch

from agents.checkpoint import checkpoint, checkpoint_path, read_checkpoint, write_checkpoint


def test_checkpoint_round_trip(tmp_path):
    state = {"actor_state_dict": {"w": torch.arange(3.0)}, "optimizer_state_dict": {"lr": 0.1}}
    path = write_checkpoint(tmp_path, checkpoint(state, 4, 61.5))
    assert path == checkpoint_path(tmp_path) == tmp_path / "checkpoints" / "last.pt"
    assert [p.name for p in path.parent.iterdir()] == ["last.pt"]  # no temporary file left
    loaded = read_checkpoint(tmp_path)
    assert loaded["iteration"] == 4 and loaded["elapsed_s"] == 61.5
    assert torch.equal(loaded["actor_state_dict"]["w"], torch.arange(3.0))
    assert torch.load(path, weights_only=True)["optimizer_state_dict"] == {"lr": 0.1}


def test_a_new_checkpoint_replaces_the_old(tmp_path):
    write_checkpoint(tmp_path, checkpoint({}, 1, 1.0))
    write_checkpoint(tmp_path, checkpoint({}, 2, 2.0))
    assert read_checkpoint(tmp_path)["iteration"] == 2
