"""``OnnxRunner``: drive a car with a policy graph in the submission convention.

The one place where an ONNX policy's output becomes an action, for submitted models
(:func:`submissions.load_policy`), the league's races and self-play opponents. The graph
takes one input per sensor with a leading batch dimension and returns ``(batch, n)``
logits (discrete: the action is the argmax) or ``(batch, 2)`` actions (continuous:
clipped to ``[-1, 1]``); see ``docs/model-format.md``. What happens to NaN or inf in that
output is the caller's explicit choice, :data:`NonFiniteRule`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import onnxruntime as ort

from submissions.format import InputSpec
from submissions.onnx_checks import open_session

NonFiniteRule = Literal["zero", "raise"]
NON_FINITE_RULES: tuple[NonFiniteRule, ...] = ("zero", "raise")


class ModelFault(RuntimeError):
    """A policy graph failed on an observation: onnxruntime could not run it, or its
    output is not the ``(batch, width)`` the model declares."""


class NonFiniteOutput(ModelFault, ValueError):
    """A policy graph output NaN or inf under the ``"raise"`` rule."""


_ORT_PREFIX = re.compile(r"^\[ONNXRuntimeError\] : \d+ : \w+ : ")
_ORT_NODE = re.compile(r"while running (\w+) node")
_ORT_SOURCE = re.compile(r"^/\S+:\d+ (?:[^()]*\([^()]*\)\s*(?:const\s*)?)?")


def _ort_reason(error: Exception) -> str:
    """What an onnxruntime error says, without its status code, source path or C++
    function: ``" in a Reshape node: The input tensor cannot be reshaped ..."``."""
    text = _ORT_PREFIX.sub("", " ".join(str(error).split())) or type(error).__name__
    node = _ORT_NODE.search(text)
    message = _ORT_SOURCE.sub("", text.rsplit("Status Message: ", 1)[-1])
    return (f" in a {node.group(1)} node" if node else "") + f": {message[:300]}"


def graph_inputs(session: ort.InferenceSession) -> list[InputSpec]:
    """The inputs a session declares, per sample: ``uint8`` if the graph says so, else
    ``float32``; a dimension the graph leaves open is ``-1`` (numpy fills it in)."""
    return [
        InputSpec(
            name=i.name,
            shape=tuple(d if isinstance(d, int) else -1 for d in i.shape[1:]),
            dtype="uint8" if "uint8" in i.type else "float32",
        )
        for i in session.get_inputs()
    ]


class OnnxRunner:
    """Runs a policy graph on observations and turns its output into actions.

    Args:
        session: an onnxruntime session of the graph.
        inputs: the graph's inputs (sensor names, per-sample shapes and dtypes).
        discrete: the output is logits (argmax) rather than two action values.
        non_finite: ``"zero"`` sanitises NaN and inf (a non-finite logit never wins; if no
            logit is finite the action is index 0; a non-finite continuous value becomes 0)
            and drives on; ``"raise"`` raises :class:`NonFiniteOutput`, naming ``name``
            and the run that produced it.
        name: how errors name the driver (e.g. ``"car entry7"``).
        width: the output's declared width (the number of discrete actions, or 2); an
            output of another shape raises :class:`ModelFault`. ``None``: not checked.

    onnxruntime failing on an observation raises :class:`ModelFault` too, so a race can
    retire the car (:class:`arena.race.StepGuard`) instead of failing. The runner is
    stateless, so ``reset`` does nothing.
    """

    def __init__(
        self,
        session: ort.InferenceSession,
        inputs: Sequence[InputSpec],
        discrete: bool,
        *,
        non_finite: NonFiniteRule = "zero",
        name: str = "policy",
        width: int | None = None,
    ) -> None:
        if non_finite not in NON_FINITE_RULES:
            raise ValueError(f"non_finite must be one of {NON_FINITE_RULES}, got {non_finite!r}")
        self.session = session
        self.discrete = discrete
        self.non_finite = non_finite
        self.name = name
        self.width = width
        self.runs = 0
        self._dtypes = {s.name: np.dtype(s.dtype) for s in inputs}
        self._shapes = {s.name: s.shape for s in inputs}

    @property
    def input_names(self) -> tuple[str, ...]:
        """The sensors the graph reads."""
        return tuple(self._dtypes)

    @classmethod
    def from_graph(
        cls, graph: bytes, discrete: bool, *, non_finite: NonFiniteRule, name: str = "policy"
    ) -> OnnxRunner:
        """A runner of raw ONNX bytes (one thread), its inputs read from the graph."""
        session = open_session(graph, intra_op_threads=1)
        return cls(session, graph_inputs(session), discrete, non_finite=non_finite, name=name)

    def reset(self) -> None:
        """Nothing to forget: the graph has no state."""

    def _feeds(self, observations: dict[str, Any], batched: bool) -> dict[str, np.ndarray]:
        feeds = {}
        for name, dtype in self._dtypes.items():
            value = np.asarray(observations[name], dtype=dtype)
            feeds[name] = value if batched else value.reshape((1, *self._shapes[name]))
        return feeds

    def _run(self, feeds: dict[str, np.ndarray]) -> np.ndarray:
        """The graph's output for ``feeds`` as float32, the non-finite rule applied."""
        self.runs += 1
        try:
            raw = np.asarray(self.session.run(None, feeds)[0], dtype=np.float32)
        except Exception as error:  # onnxruntime's errors share no base class but Exception
            raise ModelFault(
                f"{self.name}: onnxruntime failed at step {self.runs}{_ort_reason(error)}"
            ) from error
        batch = len(next(iter(feeds.values()))) if feeds else 1
        if raw.ndim != 2 or raw.shape[0] != batch or raw.shape[1] != (self.width or raw.shape[1]):
            want = f"({batch}, {self.width or 'n'})"
            raise ModelFault(
                f"{self.name}: the model output shape {raw.shape} at step {self.runs}, not {want}"
            )
        if self.non_finite == "raise" and not np.all(np.isfinite(raw)):
            raise NonFiniteOutput(f"{self.name}: the model output NaN or inf at step {self.runs}")
        return raw

    def _actions(self, raw: np.ndarray) -> np.ndarray:
        if self.discrete:
            return np.argmax(np.where(np.isfinite(raw), raw, -np.inf), axis=1)
        return np.clip(np.nan_to_num(raw, nan=0.0, posinf=0.0, neginf=0.0), -1.0, 1.0)

    def act_batch(self, observations: dict[str, Any]) -> np.ndarray:
        """Actions for a batch (leading dimension) of observations: int indices or (B, 2)."""
        return self._actions(self._run(self._feeds(observations, batched=True)))

    def act(self, observation: dict[str, Any]) -> int | np.ndarray:
        """The action for one observation: an index (discrete) or two floats (continuous)."""
        action = self._actions(self._run(self._feeds(observation, batched=False)))[0]
        return int(action) if self.discrete else action.astype(np.float32)
