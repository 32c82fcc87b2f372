"""Checks of ``policy.onnx``: static graph checks, then behaviour under onnxruntime.

The graph is only ever parsed as protobuf data and run by onnxruntime's built-in CPU
operators from an allowlist; nothing in it can name a file, a library or a function.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import onnx
import onnxruntime as ort

from arena.sensors_spec import sensor_space
from submissions.format import MEMORY_WORDS, POLICY_MEMBER, InputSpec, Limits, Problem, short
from submissions.graph_cost import graph_cost
from submissions.metadata import CheckedMetadata

ALLOWED_OPS: frozenset[str] = frozenset(
    {
        # linear algebra and arithmetic
        "Gemm", "MatMul", "Add", "Sub", "Mul", "Div", "Neg", "Abs", "Sqrt", "Pow", "Exp",
        "Log", "Reciprocal", "Max", "Min", "Sum", "Mean",
        # activations
        "Relu", "LeakyRelu", "PRelu", "Elu", "Selu", "Celu", "Gelu", "Sigmoid", "HardSigmoid",
        "HardSwish", "Tanh", "Softplus", "Softsign", "Erf", "Softmax", "LogSoftmax", "Clip",
        # convolution, pooling and normalisation
        "Conv", "MaxPool", "AveragePool", "GlobalAveragePool", "GlobalMaxPool",
        "BatchNormalization", "InstanceNormalization", "LayerNormalization",
        # shapes and plumbing
        "Flatten", "Reshape", "Transpose", "Squeeze", "Unsqueeze", "Concat", "Split", "Slice",
        "Gather", "Shape", "Cast", "Identity", "Constant", "Dropout",
        # reductions
        "ReduceMean", "ReduceSum", "ReduceMax", "ReduceMin", "ArgMax",
    }
)  # fmt: skip
DEFAULT_DOMAINS = ("", "ai.onnx")
_ELEM_TYPES = {"uint8": onnx.TensorProto.UINT8, "float32": onnx.TensorProto.FLOAT}


def _problem(where: str, expected: str, found: str, message: str) -> Problem:
    field = f"{POLICY_MEMBER}:{where}" if where else POLICY_MEMBER
    return Problem(field=field, expected=expected, found=found, message=message)


def _walk_graphs(graph: onnx.GraphProto, path: str = "") -> Iterator[tuple[str, onnx.GraphProto]]:
    yield path, graph
    for i, node in enumerate(graph.node):
        for attr in node.attribute:
            for j, sub in enumerate([attr.g] if attr.HasField("g") else list(attr.graphs)):
                yield from _walk_graphs(sub, f"{path}node[{i}].{attr.name}[{j}].")


def _tensors(model: onnx.ModelProto) -> Iterator[tuple[str, onnx.TensorProto]]:
    """Every tensor stored in the model, with a path naming where it sits."""
    for path, graph in _walk_graphs(model.graph):
        for i, tensor in enumerate(graph.initializer):
            yield f"{path}initializer[{i}]", tensor
        for i, sparse in enumerate(graph.sparse_initializer):
            yield f"{path}sparse_initializer[{i}].values", sparse.values
            yield f"{path}sparse_initializer[{i}].indices", sparse.indices
        for i, node in enumerate(graph.node):
            for attr in node.attribute:
                tensors = ([attr.t] if attr.HasField("t") else []) + list(attr.tensors)
                for tensor in tensors:
                    yield f"{path}node[{i}].{attr.name}", tensor
                if attr.HasField("sparse_tensor"):
                    yield f"{path}node[{i}].{attr.name}", attr.sparse_tensor.values


def _external_data_problems(model: onnx.ModelProto) -> list[Problem]:
    return [
        _problem(
            where,
            "data stored inside the file",
            short(tensor.name or "(unnamed tensor)"),
            "Tensors with external data are refused: the file must be self-contained.",
        )
        for where, tensor in _tensors(model)
        if tensor.data_location == onnx.TensorProto.EXTERNAL or len(tensor.external_data) > 0
    ]


def _opset_problems(model: onnx.ModelProto, limits: Limits) -> list[Problem]:
    versions = [o.version for o in model.opset_import if o.domain in DEFAULT_DOMAINS]
    wanted = f"default-domain opset {limits.min_opset}..{limits.max_opset}"
    if len(versions) != 1:
        return [
            _problem(
                "opset_import",
                wanted,
                short(versions),
                "The model must import the default ONNX domain exactly once.",
            )
        ]
    if not limits.min_opset <= versions[0] <= limits.max_opset:
        return [
            _problem(
                "opset_import",
                wanted,
                str(versions[0]),
                "The default-domain opset version is outside the supported range.",
            )
        ]
    return []


def _node_problems(model: onnx.ModelProto, limits: Limits) -> list[Problem]:
    problems = []
    if len(model.functions) > 0:
        names = [f.name for f in model.functions]
        problems.append(
            _problem("functions", "none", short(names), "Model-local functions are refused.")
        )
    nodes = model.graph.node
    if len(nodes) > limits.max_nodes:
        return [
            _problem(
                "graph",
                f"<= {limits.max_nodes} nodes",
                str(len(nodes)),
                "The graph has too many nodes.",
            )
        ]
    for i, node in enumerate(nodes):
        where = f"node[{i}]"
        op = short(f"{node.domain}:{node.op_type}" if node.domain else node.op_type, 60)
        if node.domain not in DEFAULT_DOMAINS:
            problems.append(
                _problem(
                    where,
                    "an operator of the default ONNX domain",
                    op,
                    "Operators outside the default ONNX domain are refused.",
                )
            )
        elif node.op_type not in ALLOWED_OPS:
            problems.append(
                _problem(
                    where,
                    "an operator from the allowlist",
                    op,
                    "The operator is not on the allowlist.",
                )
            )
        if any(
            a.type in (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS)
            for a in node.attribute
        ):
            problems.append(
                _problem(where, "no subgraph", op, "Subgraphs (control flow) are refused.")
            )
    return problems


def _parameter_problems(model: onnx.ModelProto, limits: Limits) -> list[Problem]:
    count = sum(int(np.prod([max(int(d), 0) for d in t.dims])) for _, t in _tensors(model))
    if count > limits.max_parameters:
        return [
            _problem(
                "graph",
                f"<= {limits.max_parameters} stored values",
                str(count),
                "The network stores too many weights.",
            )
        ]
    return []


def _dims(value: onnx.ValueInfoProto) -> list[int | str] | None:
    """Declared dims of a tensor value: ints, symbolic names ('' when unnamed), None if unknown."""
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or not tensor.HasField("shape"):
        return None
    return [d.dim_value if d.HasField("dim_value") else d.dim_param for d in tensor.shape.dim]


def _batch_ok(dims: list[int | str]) -> bool:
    return bool(dims) and (isinstance(dims[0], str) or dims[0] == 1)


def _shape_message(spec: InputSpec, dims: list[int | str], stack_size: int) -> str:
    """Why an input's shape is refused; names the stack size the graph's shape implies."""
    message = f"The input shape does not match the sensor with stack_size {stack_size}."
    frame = spec.shape[-1] // stack_size
    found = dims[1:]
    same_lead = len(found) == len(spec.shape) and tuple(found[:-1]) == spec.shape[:-1]
    last = found[-1] if found else None
    if same_lead and isinstance(last, int) and last > 0 and last % frame == 0:
        message += f" The graph reads {last // frame} frame(s): declare that stack_size."
    return message


def _io_problems(
    model: onnx.ModelProto, spec: tuple[InputSpec, ...], size: int, stack_size: int = 1
) -> list[Problem]:
    graph = model.graph
    names = [v.name for v in graph.input]
    wanted = [s.name for s in spec]
    if sorted(names) != sorted(wanted):
        return [
            _problem(
                "graph.input",
                short(wanted),
                short(names),
                "The graph inputs must be exactly the declared sensors, named after them.",
            )
        ]
    problems = []
    by_name = {v.name: v for v in graph.input}
    for s in spec:
        value = by_name[s.name]
        want = f"{s.dtype} (batch, {', '.join(map(str, s.shape))})"
        dims = _dims(value)
        elem = value.type.tensor_type.elem_type
        if elem != _ELEM_TYPES[s.dtype] or dims is None or not _batch_ok(dims):
            problems.append(
                _problem(
                    f"input:{s.name}",
                    want,
                    f"type {elem}, dims {short(dims)}",
                    "The input has the wrong element type or batch dimension.",
                )
            )
        elif tuple(dims[1:]) != s.shape:
            problems.append(
                _problem(
                    f"input:{s.name}",
                    want,
                    short(dims),
                    _shape_message(s, dims, stack_size),
                )
            )
    if len(graph.output) != 1:
        found = short([v.name for v in graph.output])
        return [
            *problems,
            _problem(
                "graph.output",
                "exactly one output",
                found,
                "The graph must have exactly one output.",
            ),
        ]
    out = graph.output[0]
    dims = _dims(out)
    want = f"float32 (batch, {size})"
    if out.type.tensor_type.elem_type != onnx.TensorProto.FLOAT or dims is None:
        found = f"type {out.type.tensor_type.elem_type}, dims {short(dims)}"
        problems.append(
            _problem(
                f"output:{short(out.name)}",
                want,
                found,
                "The output has the wrong element type or no shape.",
            )
        )
    elif len(dims) != 2 or not _batch_ok(dims) or dims[1] != size:
        problems.append(
            _problem(
                f"output:{short(out.name)}",
                want,
                short(dims),
                "The output shape does not match the action space.",
            )
        )
    return problems


def _cost_problems(model: onnx.ModelProto, limits: Limits) -> list[Problem]:
    cost = graph_cost(model)
    problems = []
    if cost.computed_bytes > limits.max_computed_bytes and cost.largest is not None:
        largest = cost.largest
        problems.append(
            _problem(
                "graph",
                f"<= {limits.max_computed_bytes} bytes computed per batch-1 step",
                short(
                    f"{cost.computed_bytes} bytes; the largest is {largest.name!r}, "
                    f"shape {largest.dims}, {largest.bytes} bytes",
                    200,
                ),
                "The graph computes tensors too large for a race's memory.",
            )
        )
    if cost.macs > limits.max_step_macs:
        problems.append(
            _problem(
                "graph",
                f"<= {limits.max_step_macs} multiply-adds per batch-1 step",
                f"{cost.macs} multiply-adds (MatMul, Gemm, Conv)",
                "The graph needs too much arithmetic to drive at race speed.",
            )
        )
    return problems


def check_graph(policy: bytes, checked: CheckedMetadata, limits: Limits) -> list[Problem]:
    """Static checks of the ONNX graph against the format and the metadata; never raises."""
    try:
        model = onnx.load_model_from_string(policy)
    except Exception as exc:
        return [
            _problem(
                "",
                "an ONNX model",
                short(f"{type(exc).__name__}: {exc}"),
                "The file is not a parsable ONNX model.",
            )
        ]
    problems = _external_data_problems(model)
    if problems:
        return problems
    try:
        onnx.checker.check_model(model)
    except Exception as exc:
        found = short(f"{type(exc).__name__}: {exc}", 200)
        return [_problem("", "a well-formed ONNX model", found, "The ONNX checker refused it.")]
    problems = _opset_problems(model, limits) or _node_problems(model, limits)
    problems = problems or _parameter_problems(model, limits)
    if problems:
        return problems
    section = checked.metadata.slipstream
    io = _io_problems(model, section.observation, section.output.size, section.stack_size)
    return io or _cost_problems(model, limits)


def open_session(policy: bytes, intra_op_threads: int = 1) -> ort.InferenceSession:
    """An onnxruntime CPU session for a policy: sequential, ``intra_op_threads`` threads,
    all graph optimisations on, quiet but for fatal errors (a failed run raises, and the
    caller reports it once)."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = intra_op_threads
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.log_severity_level = 4
    return ort.InferenceSession(policy, sess_options=options, providers=["CPUExecutionProvider"])


def _run(
    session: ort.InferenceSession, feeds: dict[str, np.ndarray], seconds: float
) -> tuple[list, float]:
    """``session.run`` with a watchdog that terminates the run after ``seconds``; its
    outputs and the CPU seconds it took.

    CPU time rather than wall time, so that other work on the machine cannot make a policy
    look slower than it is. The calling thread's clock: a session of :func:`open_session`
    with one intra-op thread runs on the caller, and unlike the process clock this one
    stays exact while an ``RLIMIT_CPU`` is set (the validation child's).
    """
    options = ort.RunOptions()
    timer = threading.Timer(seconds, lambda: setattr(options, "terminate", True))
    timer.start()
    try:
        start = time.thread_time()
        outputs = session.run(None, feeds, options)
        return outputs, time.thread_time() - start
    except Exception as exc:
        if options.terminate:
            raise TimeoutError(f"one run took over {seconds:g} s and was stopped") from exc
        raise
    finally:
        timer.cancel()


def random_inputs(
    spec: tuple[InputSpec, ...], checked: CheckedMetadata, batch: int, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """A batch of valid observations: uniform within each sensor's bounds."""
    feeds = {}
    for s in spec:
        box = sensor_space(s.name, checked.lidar_config)
        if s.dtype == "uint8":
            feeds[s.name] = rng.integers(0, 256, (batch, *s.shape), dtype=np.uint8)
        else:
            low, high = float(np.min(box.low)), float(np.max(box.high))
            feeds[s.name] = rng.uniform(low, high, (batch, *s.shape)).astype(np.float32)
    return feeds


def _output_problem(outputs: list, batch: int, size: int, what: str) -> Problem | None:
    if len(outputs) != 1:
        return _problem(
            "run",
            "one output",
            str(len(outputs)),
            f"The policy returned the wrong number of outputs on {what}.",
        )
    out = np.asarray(outputs[0])
    if out.shape != (batch, size) or out.dtype != np.float32:
        found = f"{out.dtype} {out.shape}"
        return _problem(
            "run",
            f"float32 {(batch, size)}",
            found,
            f"The policy returned the wrong shape or type on {what}.",
        )
    if not np.all(np.isfinite(out)):
        bad = int(np.size(out) - np.count_nonzero(np.isfinite(out)))
        found = f"{bad} non-finite values"
        return _problem("run", "finite outputs", found, f"The policy outputs NaN or inf on {what}.")
    return None


def _run_problem(exc: Exception) -> Problem:
    """The problem of a session that could not be built or run; running out of memory is
    said so, quoting the allocation that failed."""
    text = f"{type(exc).__name__}: {exc}"
    words = [text.find(w) for w in MEMORY_WORDS if w in text]
    if isinstance(exc, MemoryError) or words:
        found = short(text[min(words, default=0) :], 200)
        return _problem(
            "run",
            "a policy that fits in the memory it is given",
            found,
            "onnxruntime ran out of memory loading or running the policy.",
        )
    found = short(text, 200)
    message = "onnxruntime could not load or run the policy."
    return _problem("run", "a policy onnxruntime can run", found, message)


def check_behaviour(
    policy: bytes, checked: CheckedMetadata, limits: Limits
) -> tuple[float | None, list[Problem]]:
    """Run the policy on seeded random observations and time it.

    Returns ``(batch-1 latency in ms, [])`` or ``(None, problems)``; never raises. The
    latency is the best of ``latency_runs`` runs after ``latency_warmup_runs``, in CPU
    time, so that a busy machine does not flip the verdict.
    """
    spec = checked.metadata.slipstream.observation
    size = checked.metadata.slipstream.output.size
    watchdog = limits.max_run_seconds
    try:
        session = open_session(policy, intra_op_threads=1)
        dynamic = all(not isinstance(i.shape[0], int) for i in session.get_inputs())
        rng = np.random.default_rng(limits.smoke_seed)
        for batch in limits.smoke_batch_sizes if dynamic else [1] * len(limits.smoke_batch_sizes):
            feeds = random_inputs(spec, checked, batch, rng)
            outputs, _ = _run(session, feeds, watchdog)
            problem = _output_problem(outputs, batch, size, f"batch {batch}")
            if problem:
                return None, [problem]
        feeds = random_inputs(spec, checked, 1, rng)
        for _ in range(limits.latency_warmup_runs):
            _run(session, feeds, watchdog)
        runs = [_run(session, feeds, watchdog)[1] for _ in range(limits.latency_runs)]
    except Exception as exc:
        return None, [_run_problem(exc)]
    latency = min(runs) * 1000.0
    if latency > limits.max_latency_ms:
        return latency, [
            _problem(
                "latency",
                f"<= {limits.max_latency_ms:g} ms of CPU time per step "
                f"(batch 1, one thread, best of {limits.latency_runs} runs)",
                f"{latency:.2f} ms",
                "The policy is too slow to drive at race speed.",
            )
        ]
    return latency, []
