"""Turn a validated submission into a :class:`arena.policy.Policy` backed by onnxruntime."""

from __future__ import annotations

from typing import Any

import numpy as np
import onnxruntime as ort

from arena.actions import DiscreteActionSpace
from submissions.archive import read_archive
from submissions.format import POLICY_MEMBER, Limits, Problem
from submissions.onnx_checks import open_session
from submissions.validator import (
    DEFAULT_LIMITS,
    InvalidSubmission,
    ModelInfo,
    Source,
    ValidationReport,
    read_source,
    validate,
)


class OnnxPolicy:
    """Drives a car with a submitted ONNX graph.

    Discrete spaces: the argmax of the logits (deterministic; non-finite logits never
    win). Continuous spaces: the output clipped to ``[-1, 1]`` (non-finite values become 0).
    The policy is stateless, so ``reset`` does nothing.
    """

    def __init__(self, session: ort.InferenceSession, info: ModelInfo) -> None:
        self.session = session
        self.info = info
        self._discrete = isinstance(info.action_space, DiscreteActionSpace)
        self._dtypes = {s.name: np.dtype(s.dtype) for s in info.observation}
        self._shapes = {s.name: s.shape for s in info.observation}

    def reset(self) -> None:
        """Nothing to forget: the graph has no state."""

    def _feeds(self, observations: dict[str, Any], batched: bool) -> dict[str, np.ndarray]:
        feeds = {}
        for name, dtype in self._dtypes.items():
            value = np.asarray(observations[name], dtype=dtype)
            feeds[name] = value if batched else value.reshape((1, *self._shapes[name]))
        return feeds

    def _actions(self, raw: np.ndarray) -> np.ndarray:
        if self._discrete:
            logits = np.where(np.isfinite(raw), raw, -np.inf)
            return np.argmax(logits, axis=1)
        return np.clip(np.nan_to_num(raw, nan=0.0, posinf=0.0, neginf=0.0), -1.0, 1.0)

    def act_batch(self, observations: dict[str, Any]) -> np.ndarray:
        """Actions for a batch (leading dimension) of observations: int indices or (B, 2)."""
        (raw,) = self.session.run(None, self._feeds(observations, batched=True))
        return self._actions(np.asarray(raw, dtype=np.float32))

    def act(self, observation: dict[str, Any]) -> int | np.ndarray:
        """The action for one observation: an index (discrete) or two floats (continuous)."""
        (raw,) = self.session.run(None, self._feeds(observation, batched=False))
        action = self._actions(np.asarray(raw, dtype=np.float32))[0]
        return int(action) if self._discrete else action.astype(np.float32)


def load_policy(
    source: Source, intra_op_threads: int = 1, limits: Limits = DEFAULT_LIMITS
) -> OnnxPolicy:
    """Validate a submission, then load its graph; raises :class:`InvalidSubmission`."""
    data = read_source(source, limits)
    if isinstance(data, Problem):
        raise InvalidSubmission(ValidationReport(problems=(data,)))
    report = validate(data, limits)
    members, _ = read_archive(data, limits)
    if not report.ok or report.info is None or members is None:
        raise InvalidSubmission(report)
    return OnnxPolicy(open_session(members[POLICY_MEMBER], intra_op_threads), report.info)
