"""The API reference at ``/docs``: a server-rendered page built from the app's OpenAPI.

No script and nothing from another origin: the page is HTML from our own template (with
the pages' stylesheet and header), so it runs under the same CSP as every page, on the
origin where a racer's token is stored. The machine-readable spec stays at
``/openapi.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse

from league.web.routes import templates

METHODS = ("get", "post", "put", "patch", "delete")

router = APIRouter(include_in_schema=False)


@dataclass
class Parameter:
    """One path, query or header parameter, or one field of a schema."""

    name: str
    where: str
    type: str
    required: bool
    description: str = ""


@dataclass
class Operation:
    """One route as the reference shows it."""

    method: str
    path: str
    summary: str
    description: str
    needs_token: bool
    parameters: list[Parameter] = field(default_factory=list)
    body: str | None = None
    responses: list[tuple[str, str, str]] = field(default_factory=list)


def type_name(schema: dict[str, Any]) -> str:
    """A short name for a JSON schema: ``EventOut``, ``list[int]``, ``str | null``."""
    if "$ref" in schema:
        return schema["$ref"].rsplit("/", 1)[-1]
    for key in ("anyOf", "oneOf", "allOf"):
        if key in schema:
            return " | ".join(type_name(s) for s in schema[key])
    if "enum" in schema:
        return " | ".join(repr(v) for v in schema["enum"])
    kind = schema.get("type", "any")
    if kind == "array":
        return f"list[{type_name(schema.get('items', {}))}]"
    return str(kind)


def _body_type(operation: dict[str, Any]) -> str | None:
    content = operation.get("requestBody", {}).get("content", {})
    for media, item in content.items():
        return f"{media}: {type_name(item.get('schema', {}))}"
    return None


def _responses(operation: dict[str, Any]) -> list[tuple[str, str, str]]:
    rows = []
    for code, answer in operation.get("responses", {}).items():
        schema = answer.get("content", {}).get("application/json", {}).get("schema")
        rows.append((code, answer.get("description", ""), type_name(schema) if schema else ""))
    return rows


def operations(spec: dict[str, Any]) -> list[Operation]:
    """Every operation of ``spec`` in path order."""
    found = []
    for path, item in spec.get("paths", {}).items():
        for method in METHODS:
            if method not in item:
                continue
            op = item[method]
            parameters = [
                Parameter(
                    p["name"],
                    p["in"],
                    type_name(p.get("schema", {})),
                    p.get("required", False),
                    p.get("description", ""),
                )
                for p in op.get("parameters", [])
            ]
            found.append(
                Operation(
                    method=method.upper(),
                    path=path,
                    summary=op.get("summary", ""),
                    description=op.get("description", ""),
                    needs_token=bool(op.get("security")),
                    parameters=parameters,
                    body=_body_type(op),
                    responses=_responses(op),
                )
            )
    return found


def schemas(spec: dict[str, Any]) -> dict[str, list[Parameter]]:
    """Each named schema of ``spec`` with its fields."""
    named = spec.get("components", {}).get("schemas", {})
    return {
        name: [
            Parameter(
                prop,
                "field",
                type_name(sub),
                prop in schema.get("required", []),
                sub.get("description", ""),
            )
            for prop, sub in schema.get("properties", {}).items()
        ]
        for name, schema in sorted(named.items())
    }


@router.get("/docs", response_class=HTMLResponse)
def docs_page(request: Request) -> HTMLResponse:
    """The API reference: every route, its parameters, body and answers, and the schemas."""
    spec = request.app.openapi()
    context = {"spec": spec, "operations": operations(spec), "schemas": schemas(spec)}
    return templates.TemplateResponse(request, "docs.html", context)
