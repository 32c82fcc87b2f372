"""Safe reading of an uploaded zip archive: structural checks and capped extraction.

Nothing here trusts the sizes written in zip headers: declared sizes are checked first
(cheap refusal), then every member is stream-decompressed under a running byte cap.
"""

from __future__ import annotations

import io
import stat
import zipfile

from submissions.format import ALLOWED_MEMBERS, REQUIRED_MEMBERS, Limits, Problem, short

_CHUNK = 64 * 1024
_ALLOWED_METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflated"}


def _problem(field: str, expected: str, found: str, message: str) -> Problem:
    return Problem(field=field, expected=expected, found=found, message=message)


def _name_problems(info: zipfile.ZipInfo) -> list[Problem]:
    """Path, type and encryption problems of one member, judged from its header alone."""
    name = info.filename
    field = f"archive:{short(name, 60)}"
    parts = name.replace("\\", "/").split("/")
    if name.startswith(("/", "\\")) or (len(name) > 1 and name[1] == ":"):
        return [_problem(field, "a relative name", short(name), "Absolute paths are refused.")]
    if ".." in parts:
        return [_problem(field, "no '..' component", short(name), "Path traversal is refused.")]
    if stat.S_ISLNK(info.external_attr >> 16):
        return [_problem(field, "a regular file", "a symlink", "Symlink members are refused.")]
    if name not in ALLOWED_MEMBERS:
        return [
            _problem(
                field,
                f"one of {list(ALLOWED_MEMBERS)}",
                short(name),
                "The archive holds a member the format does not allow.",
            )
        ]
    if info.flag_bits & 0x1:
        return [_problem(field, "not encrypted", "encrypted", "Encrypted members are refused.")]
    if info.compress_type not in _ALLOWED_METHODS:
        return [
            _problem(
                field,
                "stored or deflated",
                f"compression method {info.compress_type}",
                "Only stored and deflated members are accepted.",
            )
        ]
    return []


def _declared_size_problems(infos: list[zipfile.ZipInfo], limits: Limits) -> list[Problem]:
    """Refuse on the sizes the headers declare (a liar is caught later while reading)."""
    problems = []
    total = 0
    for info in infos:
        total += info.file_size
        cap = limits.member_cap(info.filename)
        if info.file_size > cap:
            problems.append(
                _problem(
                    f"archive:{info.filename}",
                    f"at most {cap} bytes uncompressed",
                    f"{info.file_size} bytes declared",
                    "The member is larger than the format allows.",
                )
            )
        big = info.file_size >= limits.ratio_check_min_bytes
        ratio = info.file_size / max(info.compress_size, 1)
        if big and ratio > limits.max_compression_ratio:
            problems.append(
                _problem(
                    f"archive:{info.filename}",
                    f"compression ratio at most {limits.max_compression_ratio:g}",
                    f"{ratio:.0f}",
                    "The member compresses suspiciously well (zip bomb guard).",
                )
            )
    if total > limits.max_total_uncompressed_bytes:
        problems.append(
            _problem(
                "archive",
                f"at most {limits.max_total_uncompressed_bytes} bytes uncompressed in all",
                f"{total} bytes declared",
                "The archive expands to more than the format allows.",
            )
        )
    return problems


def _read_capped(zf: zipfile.ZipFile, info: zipfile.ZipInfo, cap: int) -> bytes | None:
    """Decompress one member, giving up (None) as soon as it passes ``cap`` bytes."""
    out = bytearray()
    with zf.open(info) as stream:
        while chunk := stream.read(_CHUNK):
            out += chunk
            if len(out) > cap:
                return None
    return bytes(out)


def _open_zip(data: bytes, limits: Limits) -> tuple[zipfile.ZipFile | None, list[Problem]]:
    if not data:
        return None, [_problem("archive", "a zip archive", "an empty file", "The file is empty.")]
    if len(data) > limits.max_archive_bytes:
        return None, [
            _problem(
                "archive",
                f"at most {limits.max_archive_bytes} bytes",
                f"{len(data)} bytes",
                "The archive is larger than the upload limit.",
            )
        ]
    try:
        return zipfile.ZipFile(io.BytesIO(data)), []
    except Exception as exc:
        return None, [
            _problem(
                "archive",
                "a zip archive",
                short(f"{type(exc).__name__}: {exc}"),
                "The file is not a readable zip archive.",
            )
        ]


def _header_problems(infos: list[zipfile.ZipInfo], limits: Limits) -> list[Problem]:
    if len(infos) > limits.max_members:
        return [
            _problem(
                "archive",
                f"at most {limits.max_members} members",
                f"{len(infos)} members",
                "The archive has too many members.",
            )
        ]
    names = [info.filename for info in infos]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        return [
            _problem(
                "archive",
                "unique member names",
                short(duplicates),
                "The archive lists the same member more than once.",
            )
        ]
    problems = [p for info in infos for p in _name_problems(info)]
    problems += [
        _problem(
            "archive",
            f"a member named {name}",
            "none",
            f"The archive lacks the required member {name}.",
        )
        for name in REQUIRED_MEMBERS
        if name not in names
    ]
    return problems


def read_archive(data: bytes, limits: Limits) -> tuple[dict[str, bytes] | None, list[Problem]]:
    """Check an archive's structure and extract its members under every cap.

    Returns ``(members, [])`` on success and ``(None, problems)`` otherwise; never raises.
    """
    zf, problems = _open_zip(data, limits)
    if zf is None:
        return None, problems
    with zf:
        infos = zf.infolist()
        problems = _header_problems(infos, limits) or _declared_size_problems(infos, limits)
        if problems:
            return None, problems
        members: dict[str, bytes] = {}
        budget = limits.max_total_uncompressed_bytes
        for info in infos:
            cap = min(limits.member_cap(info.filename), budget)
            try:
                content = _read_capped(zf, info, cap)
            except Exception as exc:
                return None, [
                    _problem(
                        f"archive:{info.filename}",
                        "an intact member",
                        short(f"{type(exc).__name__}: {exc}"),
                        "The member could not be decompressed (corrupt or truncated archive).",
                    )
                ]
            if content is None:
                return None, [
                    _problem(
                        f"archive:{info.filename}",
                        f"at most {cap} bytes uncompressed",
                        "more while decompressing",
                        "The member expands beyond its cap; its header understates its size.",
                    )
                ]
            members[info.filename] = content
            budget -= len(content)
    return members, []
