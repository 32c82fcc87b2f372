"""Turn a validated submission into a :class:`arena.policy.Policy` backed by onnxruntime."""

from __future__ import annotations

import onnxruntime as ort

from arena.actions import DiscreteActionSpace
from submissions.archive import read_archive
from submissions.format import POLICY_MEMBER, Limits, Problem
from submissions.onnx_checks import open_session
from submissions.runner import NonFiniteRule, OnnxRunner
from submissions.validator import (
    DEFAULT_LIMITS,
    InvalidSubmission,
    ModelInfo,
    Source,
    ValidationReport,
    read_source,
    validate,
)


class OnnxPolicy(OnnxRunner):
    """Drives a car with a submitted ONNX graph; ``info`` is what the submission declares.

    The inputs and the action space come from ``info``; everything else is
    :class:`submissions.runner.OnnxRunner` (argmax of the logits or the output clipped to
    ``[-1, 1]``, and the ``non_finite`` rule: ``"zero"`` unless the caller says otherwise).
    """

    def __init__(
        self,
        session: ort.InferenceSession,
        info: ModelInfo,
        *,
        non_finite: NonFiniteRule = "zero",
        name: str = "policy",
    ) -> None:
        discrete = isinstance(info.action_space, DiscreteActionSpace)
        width = info.action_space.n if discrete else 2
        super().__init__(
            session, info.observation, discrete, non_finite=non_finite, name=name, width=width
        )
        self.info = info


def load_policy(
    source: Source,
    intra_op_threads: int = 1,
    limits: Limits = DEFAULT_LIMITS,
    *,
    non_finite: NonFiniteRule = "zero",
    name: str = "policy",
    run_policy: bool = True,
) -> OnnxPolicy:
    """Validate a submission, then load its graph; raises :class:`InvalidSubmission`.

    ``non_finite`` and ``name`` are the runner's (:class:`submissions.runner.OnnxRunner`).
    ``run_policy=False`` skips the behaviour stage (sample runs on random observations)
    and keeps the archive, metadata and static graph checks: for a file that passed full
    validation when it was stored and whose bytes were checked against that sha256.
    """
    data = read_source(source, limits)
    if isinstance(data, Problem):
        raise InvalidSubmission(ValidationReport(problems=(data,)))
    report = validate(data, limits, run_policy=run_policy)
    members, _ = read_archive(data, limits)
    if not report.ok or report.info is None or members is None:
        raise InvalidSubmission(report)
    session = open_session(members[POLICY_MEMBER], intra_op_threads)
    return OnnxPolicy(session, report.info, non_finite=non_finite, name=name)
