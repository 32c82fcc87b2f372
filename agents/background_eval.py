"""Evaluation races in a process of their own, so that training goes on while one runs.

The trainer hands over the actor's weights after an evaluated iteration and takes the
race's result one iteration later (:class:`agents.train.Trainer`); the process races one
set of weights at a time, with one torch thread, in the run's evaluation races against its
evaluation opponent, as an evaluation in the trainer's own process would.
"""

from __future__ import annotations

import traceback
from dataclasses import replace
from typing import Any

import torch

from agents import evaluate
from agents.processes import ignore_stop_signals, spawn_helper
from agents.run import Run
from arena.race import RaceResult


def _serve(conn: Any, run: Run) -> None:
    """The evaluation process: race every set of actor weights received in the run's
    evaluation races until told to stop (None)."""
    ignore_stop_signals()  # the trainer handles them and closes this process
    torch.set_num_threads(1)
    try:
        configs = run.evaluation_configs()
        reward = run.reward
        opponent = evaluate.run_opponent(run.settings)
    except Exception:
        conn.send(("error", traceback.format_exc(limit=3)))
        return
    while (weights := conn.recv()) is not None:
        try:
            actor = run.actor(checkpoint={"actor_state_dict": weights})
            policy = evaluate.TorchPolicy(actor, run.settings.discrete)
            races = [
                evaluate.evaluate_policy(c, policy, reward_function=reward, opponent=opponent)
                for c in configs
            ]
            conn.send(("ok", races))
        except Exception:
            conn.send(("error", traceback.format_exc(limit=3)))


class BackgroundEvaluator:
    """A spawned process that races a run's actor weights in its evaluation races, one set
    at a time.

    ``submit`` hands it the actor's weights (copied, so training may change them at once);
    ``result`` waits for those races. The stop signals are ignored there: the trainer
    handles them and calls ``close``.
    """

    def __init__(self, run: Run) -> None:
        # A copy without the resolved reward function: the process resolves its own.
        self._conn, self._proc = spawn_helper(_serve, replace(run))
        self._busy = False

    def submit(self, actor: torch.nn.Module) -> None:
        """Start racing ``actor``'s weights (one race at a time: take the last result first)."""
        if self._busy:
            raise RuntimeError("take the last evaluation's result before submitting another")
        self._conn.send({k: v.detach().cpu().clone() for k, v in actor.state_dict().items()})
        self._busy = True

    def result(self) -> list[RaceResult]:
        """The submitted evaluation's races (:meth:`agents.run.Run.evaluation_configs`),
        once they have run."""
        if not self._busy:
            raise RuntimeError("no evaluation was submitted")
        try:
            status, payload = self._conn.recv()  # Ctrl-C here leaves it busy: close stops it
        except EOFError:
            raise RuntimeError("the evaluation process exited unexpectedly") from None
        self._busy = False
        if status == "error":
            raise RuntimeError(f"evaluation failed: {payload}")
        return payload

    def close(self) -> None:
        """Stop the process (at once, if it is racing)."""
        if self._proc.is_alive():
            if self._busy:
                self._proc.terminate()
            else:
                try:
                    self._conn.send(None)
                except (BrokenPipeError, OSError):
                    self._proc.terminate()
            self._proc.join(timeout=10)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
        self._conn.close()
