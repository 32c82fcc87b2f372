"""``slipstream model pack``: a submission from a training run, or from a graph trained elsewhere.

``pack RUN`` packs a Slipstream run's model, its best evaluation's, or another of its
checkpoints with ``--checkpoint`` (:meth:`agents.run.Run.pack`);
``pack --onnx policy.onnx --metadata model_metadata.json`` takes any trainer's ONNX graph
and a DeepRacer metadata file, fills Slipstream's section from the graph
(:func:`submissions.from_graph.derive_section`) and packs them. Either way the archive is
validated before it is moved to ``--out``: nothing is written unless it is valid. It lives
in ``agents`` (mounted on the ``model`` group by ``slipstream.cli``) because it reads runs
and DeepRacer metadata, which ``submissions`` does not know about.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich.text import Text

from agents.checkpoint import Which
from agents.model_metadata import DeepRacerMetadata, ModelMetadataError, read_model_metadata
from submissions.cli import console, print_info, print_problems
from submissions.from_graph import GraphSection, GraphSpecError, derive_section
from submissions.pack import pack
from submissions.validator import validate


def _fail(message: str) -> NoReturn:
    """Print ``message`` (plain text: it may quote untrusted input) and exit 2."""
    console.print(Text(message, style="red"), soft_wrap=True)
    raise typer.Exit(2)


def _describe(section: GraphSection) -> str:
    inputs = "; ".join(f"{s.name} {s.dtype}{list(s.shape)}" for s in section.observation)
    frames = f", {section.stack_size} stacked frames" if section.stack_size > 1 else ""
    output = f"{section.output.size} {section.output.convention}"
    return f"graph: inputs {inputs}{frames}; output {output}"


def _pack_graph(tmp: Path, graph: Path, metadata: Path, extras: dict[str, Any]) -> None:
    """Pack ``graph`` with ``metadata`` into ``tmp``, the section derived from the graph."""
    try:
        meta: DeepRacerMetadata = read_model_metadata(metadata)
        policy = graph.read_bytes()
    except ModelMetadataError as exc:
        _fail(f"{metadata}: {exc}")
    except OSError as exc:
        _fail(f"cannot read {graph}: {exc.strerror}")
    try:
        section = derive_section(policy, meta.action_space, meta.sensors, meta.lidar_config)
    except GraphSpecError as exc:
        console.print(Text("the graph does not fit model_metadata.json:", style="red"))
        for sentence in exc.problems:
            console.print(Text(f"- {sentence}"), soft_wrap=True)
        raise typer.Exit(2) from None
    console.print(Text(_describe(section)), soft_wrap=True)
    pack(
        tmp,
        policy,
        meta.action_space,
        meta.sensors,
        neural_network=meta.neural_network,
        training_algorithm=meta.training_algorithm,
        lidar_config=meta.lidar_config,
        stack_size=section.stack_size,
        **extras,
    )


def _pack_run(tmp: Path, run: Path, which: Which | None) -> None:
    from agents.checkpoint import checkpoint_path
    from agents.run import Run  # torch: only for this form

    if which is not None and not checkpoint_path(run, which).exists():
        _fail(f"the run {run} has no {which} checkpoint ({checkpoint_path(run, which)})")
    try:
        with console.status(f"exporting the actor of {run} to ONNX..."):
            Run.load(run).pack(tmp, which)
    except (FileNotFoundError, ValueError) as exc:
        _fail(f"cannot pack the run {run}: {exc}")


def pack_command(
    run: Annotated[
        Path | None, typer.Argument(help="A Slipstream training run folder (or use --onnx).")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="The submission to write.")] = Path(
        "model.zip"
    ),
    onnx_file: Annotated[
        Path | None, typer.Option("--onnx", help="A policy graph exported by any trainer.")
    ] = None,
    metadata: Annotated[
        Path | None, typer.Option("--metadata", help="Its DeepRacer model_metadata.json.")
    ] = None,
    reward_function: Annotated[
        Path | None, typer.Option("--reward-function", help="Reward file kept for the record.")
    ] = None,
    metrics: Annotated[
        Path | None, typer.Option("--metrics", help="Training metrics CSV kept for the record.")
    ] = None,
    checkpoint: Annotated[
        Which | None,
        typer.Option(
            "--checkpoint",
            help="The RUN's checkpoint to pack: best (by completion), fastest (by "
            "evaluation lap) or last. Default: best, else last.",
        ),
    ] = None,
) -> None:
    """Pack a submission from a training RUN, or from --onnx and --metadata.

    The graph's inputs must be named after the metadata's sensors, with their dtypes and
    shapes, and its output must fit the action space (docs/model-format.md). The result is
    validated; nothing is written unless it is valid (exit 2 otherwise).
    """
    if (run is None) == (onnx_file is None):
        raise typer.BadParameter("give a RUN folder or --onnx, not both", param_hint="RUN")
    if onnx_file is not None and metadata is None:
        raise typer.BadParameter("--onnx needs --metadata", param_hint="--metadata")
    if run is not None and (metadata or reward_function or metrics):
        raise typer.BadParameter("only with --onnx", param_hint="--metadata/--reward-function")
    if run is None and checkpoint is not None:
        raise typer.BadParameter("only with a RUN folder", param_hint="--checkpoint")
    tmp = out.with_name(f".{out.name}.partial")
    try:
        if run is not None:
            _pack_run(tmp, run, checkpoint)
        else:
            assert onnx_file is not None and metadata is not None
            extras = {"reward_function": reward_function, "metrics_csv": metrics}
            _pack_graph(tmp, onnx_file, metadata, extras)
        with console.status("validating..."):
            report = validate(tmp)
        if not report.ok:
            console.print(Text.assemble(("refused: ", "red"), f"{out} was not written"))
            print_problems(report)
            raise typer.Exit(2)
        tmp.replace(out)
    except (OSError, ValueError) as exc:
        _fail(f"cannot pack {out}: {exc}")
    finally:
        tmp.unlink(missing_ok=True)
    console.print(Text.assemble(("packed ", "green"), str(out)))
    if report.info is not None:
        print_info(report.info)
