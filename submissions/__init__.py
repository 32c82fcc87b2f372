"""Submissions: the model file format, its validator, the ONNX policy loader and runner.

Uploaded files are treated as data only: nothing in an archive is ever imported,
unpickled or executed; the policy graph runs on onnxruntime's allowlisted operators.
"""

from submissions.format import FORMAT_VERSION, InputSpec, Limits, Problem
from submissions.pack import pack
from submissions.policy import OnnxPolicy, load_policy
from submissions.runner import ModelFault, NonFiniteOutput, NonFiniteRule, OnnxRunner
from submissions.validator import InvalidSubmission, ModelInfo, ValidationReport, validate

__all__ = [
    "FORMAT_VERSION",
    "InputSpec",
    "InvalidSubmission",
    "Limits",
    "ModelFault",
    "ModelInfo",
    "NonFiniteOutput",
    "NonFiniteRule",
    "OnnxPolicy",
    "OnnxRunner",
    "Problem",
    "ValidationReport",
    "load_policy",
    "pack",
    "validate",
]
