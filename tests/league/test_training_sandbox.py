"""The training sandbox against real bubblewrap (no mocks): a confined Python reaches no
network, reads none of the caller's files or secrets, is held to its process, memory and
file-size limits, dies whole when killed, and can still do its job (write its workdir,
import the code packages). Each test also checks that the host is unharmed.

Skipped where this host cannot sandbox (:func:`probe` says why), except under ``CI=true``,
where bubblewrap is installed and a missing sandbox fails.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest

from league.training.sandbox import (
    SANDBOX_UID,
    ConfinementLimits,
    confined_popen,
    kill_confined,
    probe,
    readable_paths,
)

REASON = probe()
pytestmark = pytest.mark.skipif(
    REASON is not None and os.environ.get("CI") != "true",
    reason=f"this host cannot sandbox training code: {REASON} (CI installs bubblewrap)",
)
MiB = 1024 * 1024
SMALL = ConfinementLimits(
    memory_mb=1024, cpu_seconds=30, processes=256, file_mb=64, open_files=256, tmp_mb=16
)
PROJECT = Path(__file__).resolve().parents[2]


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """The sandbox's one writable folder, beside the test's other (private) files."""
    path = tmp_path / "work"
    path.mkdir()
    return path


def run(
    code: str,
    workdir: Path,
    limits: ConfinementLimits = SMALL,
    args: Sequence[str] = (),
    env: dict[str, str] | None = None,
    extra_readable: Sequence[Path] = (),
) -> tuple[int, str]:
    """Run ``python -c code *args`` confined; its exit code and output (stdout, stderr)."""
    argv = [sys.executable, "-c", code, *args]
    proc = confined_popen(argv, workdir, limits, env=env, extra_readable=extra_readable)
    try:
        output, _ = proc.communicate(timeout=60)
    finally:
        kill_confined(proc)
    return proc.returncode, output.decode(errors="replace")


def answer(output: str) -> dict:
    """The JSON line the child printed last."""
    try:
        return json.loads(output.strip().splitlines()[-1])
    except (IndexError, ValueError):
        pytest.fail(f"the confined child did not answer: {output!r}")


def test_host_can_sandbox() -> None:
    assert REASON is None


def test_readable_paths_are_the_code_packages_not_the_project() -> None:
    paths = readable_paths()
    for name in ("agents", "arena", "tracks", "submissions"):
        assert PROJECT / name in paths
    assert PROJECT not in paths
    assert not any(p != q and p in q.parents for p in paths for q in paths)


@pytest.fixture
def listener() -> Iterator[int]:
    """A TCP port on the host's 127.0.0.1 that accepts connections."""
    server = socket.create_server(("127.0.0.1", 0))
    try:
        yield server.getsockname()[1]
    finally:
        server.close()


CONNECT = """
import json, socket, sys
results = {}
for host, port in json.loads(sys.argv[1]):
    try:
        socket.create_connection((host, port), timeout=3).close()
        results[f"{host}:{port}"] = "connected"
    except OSError as exc:
        results[f"{host}:{port}"] = f"{type(exc).__name__}: {exc}"
results["interfaces"] = [name for _, name in socket.if_nameindex()]
print(json.dumps(results))
"""


def test_no_network_inside(workdir: Path, listener: int) -> None:
    targets = [("127.0.0.1", listener), ("127.0.0.1", 5432), ("1.1.1.1", 53)]
    socket.create_connection(("127.0.0.1", listener), timeout=3).close()  # the host can
    _, output = run(CONNECT, workdir, args=[json.dumps(targets)])
    results = answer(output)
    for host, port in targets:
        assert results[f"{host}:{port}"] != "connected", output
        assert "Error" in results[f"{host}:{port}"], output
    assert results["interfaces"] == ["lo"], output  # a network namespace of its own


def test_postgres_reachable_from_host_only(workdir: Path) -> None:
    try:
        socket.create_connection(("127.0.0.1", 5432), timeout=2).close()
    except OSError:
        pytest.skip("PostgreSQL does not listen on 127.0.0.1:5432 on this host")
    _, output = run(CONNECT, workdir, args=[json.dumps([["127.0.0.1", 5432]])])
    assert answer(output)["127.0.0.1:5432"].startswith("ConnectionRefusedError"), output


READ = """
import json, sys
results = {}
for path in sys.argv[1:]:
    try:
        with open(path) as handle:
            results[path] = "read: " + handle.read(100)
    except OSError as exc:
        results[path] = type(exc).__name__
print(json.dumps(results))
"""


def test_caller_files_are_invisible(tmp_path: Path, workdir: Path) -> None:
    database = tmp_path / "data" / "league.db"
    database.parent.mkdir()
    database.write_text("the league's rows")
    (tmp_path / ".env").write_text("SLIPSTREAM_DATABASE_URL=postgresql://secret")
    pyproject = PROJECT / "pyproject.toml"  # beside the code packages, not in them
    assert pyproject.is_file()
    hidden = [database, tmp_path / ".env", pyproject, Path("/etc/hostname"), Path("/root")]
    own = workdir / "mine.txt"
    own.write_text("the job's own file")
    _, output = run(READ, workdir, args=[*map(str, hidden), str(own)])
    results = answer(output)
    for path in hidden[:-1]:
        assert results[str(path)] == "FileNotFoundError", output
    assert results["/root"] in ("FileNotFoundError", "PermissionError", "IsADirectoryError")
    assert results[str(own)] == "read: the job's own file", output
    assert database.read_text() == "the league's rows"


def test_code_and_extra_paths_are_read_only(tmp_path: Path, workdir: Path) -> None:
    extra = tmp_path / "extra"
    extra.mkdir()
    (extra / "parent.txt").write_text("the parent model")
    code = """
import json, os
extra = os.environ["EXTRA"]
results = {"extra": open(extra + "/parent.txt").read()}
try:
    open(extra + "/new.txt", "w").write("x")
    results["write"] = "written"
except OSError as exc:
    results["write"] = type(exc).__name__
# access(), not a write: a broken sandbox must not write into the project or /usr
results["writable"] = [p for p in (extra, os.environ["TRACKS"], "/usr") if os.access(p, os.W_OK)]
print(json.dumps(results))
"""
    env = {"EXTRA": str(extra), "TRACKS": str(PROJECT / "tracks")}
    _, output = run(code, workdir, env=env, extra_readable=[extra])
    results = answer(output)
    assert results["extra"] == "the parent model", output
    assert results["write"] != "written", output
    assert results["writable"] == [], output
    assert not (extra / "new.txt").exists()


SHOW_ENV = """
import json, os
found = {"os.environ": dict(os.environ)}
for path in ("/proc/1/environ", "/proc/self/environ"):
    try:
        found[path] = open(path, "rb").read().decode(errors="replace")
    except OSError as exc:
        found[path] = type(exc).__name__
print(json.dumps(found))
"""


def test_no_secret_in_the_environment(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    secret = f"s3cr3t-{uuid.uuid4().hex}"
    monkeypatch.setenv("SLIPSTREAM_TEST_SECRET", secret)
    monkeypatch.setenv("SLIPSTREAM_DATABASE_URL", f"postgresql://league:{secret}@db/league")
    code, output = run(SHOW_ENV, workdir, env={"JOB": "mine"})
    assert code == 0, output
    assert secret not in output
    found = answer(output)
    assert found["os.environ"]["JOB"] == "mine"  # its own environment does get through
    assert found["os.environ"]["HOME"] == str(workdir)
    assert "SLIPSTREAM_TEST_SECRET" not in found["os.environ"]
    assert "HOME=" in found["/proc/self/environ"]


def test_no_secret_in_the_sandbox_processes(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Seen from the host: bwrap, its PID 1 and the confined child hold no secret (inside,
    /proc/1/environ may be unreadable: PID 1 is root's when the caller is root)."""
    secret = f"s3cr3t-{uuid.uuid4().hex}"
    monkeypatch.setenv("SLIPSTREAM_TEST_SECRET", secret)
    code = "import time; open('ready', 'w').close(); time.sleep(60)"
    proc = confined_popen([sys.executable, "-c", code], workdir, SMALL)
    try:
        _wait_for(workdir / "ready", proc)
        pids = [proc.pid, *_descendants(proc.pid)]
        assert len(pids) >= 3, pids  # bwrap, the sandbox's PID 1, the child
        environs = [Path(f"/proc/{pid}/environ").read_bytes() for pid in pids]
    finally:
        kill_confined(proc)
    assert environs[0] == b"PATH=/usr/bin:/bin\0"
    assert not any(secret.encode() in environ for environ in environs)


FORK_BOMB = """
import os, time
forked, error = 0, None
for _ in range(2000):  # capped: a broken sandbox must not take the machine down
    try:
        pid = os.fork()
    except OSError as exc:
        error = repr(exc)
        break
    if pid == 0:
        time.sleep(20)
        os._exit(0)
    forked += 1
print("FORKED", forked, error, flush=True)
"""


def test_fork_bomb_is_stopped(workdir: Path) -> None:
    limits = ConfinementLimits(memory_mb=512, cpu_seconds=30, processes=64, tmp_mb=4)
    started = time.monotonic()
    _, output = run(FORK_BOMB, workdir, limits)
    assert "FORKED" in output, output
    forked = int(output.split("FORKED")[1].split()[0])
    assert forked < 200, output
    assert "BlockingIOError" in output, output  # EAGAIN: the limit, not the cap, stopped it
    assert time.monotonic() - started < 15  # its sleeping children died with it
    # the host still can (spawned, not forked: see the fork-handler test below)
    assert subprocess.run([sys.executable, "-c", "raise SystemExit(7)"]).returncode == 7


def test_memory_limit(workdir: Path) -> None:
    code = """
results = []
for gib in (2, 50):  # bytes() is calloc: unconfined it would succeed without touching RAM
    try:
        block = bytes(gib * 1024**3)
        results.append(f"ALLOCATED {gib} GiB")
        del block
    except MemoryError:
        results.append(f"MemoryError {gib} GiB")
print(results)
"""
    _, output = run(code, workdir, ConfinementLimits(memory_mb=512, cpu_seconds=30))
    assert "MemoryError 2 GiB" in output, output
    assert "MemoryError 50 GiB" in output, output
    assert "ALLOCATED" not in output, output


def test_file_size_limit(workdir: Path) -> None:
    code = """
import sys
chunk = b"\\0" * (1 << 20)
written = 0
try:
    with open("big.bin", "wb", buffering=0) as handle:
        for _ in range(256):  # 256 MiB: a broken limit must not fill the disk
            handle.write(chunk)
            written += 1
    print("WROTE", written)
except OSError as exc:
    print("STOPPED", written, exc.errno, exc)
"""
    limits = ConfinementLimits(memory_mb=512, cpu_seconds=30, file_mb=8)
    _, output = run(code, workdir, limits)
    assert f"STOPPED 8 {errno.EFBIG}" in output, output
    assert (workdir / "big.bin").stat().st_size <= 8 * MiB


def test_confined_python_works(workdir: Path) -> None:
    marker = f"slipstream-private-tmp-{uuid.uuid4().hex}"
    code = f"""
import json, os
import tracks.catalog
with open("result.txt", "w") as handle:
    handle.write("written inside")
open("/tmp/{marker}", "w").write("private")
try:
    import league
    league_visible = True
except ImportError:
    league_visible = False
print(json.dumps({{"uid": os.getuid(), "euid": os.geteuid(), "cwd": os.getcwd(),
                  "tracks": len(tracks.catalog.builtin_names()),
                  "league_visible": league_visible}}))
"""
    code_, output = run(code, workdir)
    assert code_ == 0, output
    found = answer(output)
    assert found["cwd"] == str(workdir)
    assert found["tracks"] > 0
    assert found["league_visible"] is False  # the server's own code is not mounted
    assert (workdir / "result.txt").read_text() == "written inside"
    assert not Path("/tmp", marker).exists()  # its /tmp is its own
    if os.geteuid() == 0:
        assert found["uid"] == found["euid"] == SANDBOX_UID != 0
    else:
        assert found["uid"] == os.geteuid()


def _wait_for(path: Path, proc: subprocess.Popen[bytes], seconds: float = 20) -> None:
    """Wait until the confined child creates ``path``."""
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert proc.poll() is None, proc.stdout.read() if proc.stdout else ""
        assert time.monotonic() < deadline, f"no {path.name} after {seconds} s"
        time.sleep(0.05)


def _descendants(pid: int) -> list[int]:
    """All processes below ``pid``, from the host's /proc."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, todo = [], [pid]
    while todo:
        children = [child for child, parent in parents.items() if parent == todo[-1]]
        todo.pop()
        found += children
        todo += children
    return found


def _processes_with(marker: str) -> list[int]:
    """Host pids whose command line holds ``marker`` (the sandbox's pids differ inside)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != os.getpid():
            try:
                if marker.encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def test_kill_takes_the_whole_sandbox(workdir: Path) -> None:
    marker = f"slipstream-grandchild-{uuid.uuid4().hex}"
    # the grandchild forks an orphan (its parent exits): outside a PID namespace nothing but
    # the host's init would hold it
    orphan = "import os, time\nif os.fork() == 0:\n    time.sleep(1000)"
    code = f"""
import subprocess, sys, time
subprocess.run([sys.executable, "-c", {orphan!r}, "{marker}"], start_new_session=True)
open("ready", "w").write("started")
time.sleep(1000)
"""
    proc = confined_popen([sys.executable, "-c", code], workdir, SMALL)
    try:
        _wait_for(workdir / "ready", proc)
        seen = _processes_with(marker)  # bwrap, its PID 1, the child and the orphan
        assert len(seen) >= 4, seen
    finally:
        kill_confined(proc)
    assert proc.returncode is not None
    assert _processes_with(marker) == []
    for pid in seen:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    kill_confined(proc)  # again: a no-op


_FORKS: list[int] = []
_COUNTING = [False]
os.register_at_fork(before=lambda: _COUNTING[0] and _FORKS.append(1))


def test_starting_a_sandbox_runs_no_fork_handler_in_the_caller(workdir: Path) -> None:
    """The sandbox is spawned, not forked from the caller with a ``preexec_fn``: such a
    fork runs every library's fork handler in the threaded league server, and OpenBLAS's
    deadlocked it while another thread was in a numpy solve."""
    _COUNTING[0] = True
    try:
        code, output = run("print('ran')", workdir)
    finally:
        _COUNTING[0] = False
    assert (code, output.strip()) == (0, "ran")
    assert _FORKS == []


WEDGE = """
import sys, threading, time
from pathlib import Path
from league.training.sandbox import ConfinementLimits, confined_popen, kill_confined
from tracks.catalog import builtin_names, get_track
from tracks.raceline import compute_racing_line
counts, stop = {"lines": 0, "sandboxes": 0}, time.monotonic() + float(sys.argv[1])
def lines():
    while time.monotonic() < stop:
        for name in builtin_names():
            compute_racing_line(get_track(name))
            counts["lines"] += 1
def sandboxes():
    workdir = Path(sys.argv[2])
    while time.monotonic() < stop:
        proc = confined_popen(["/bin/true"], workdir, ConfinementLimits())
        proc.communicate()
        kill_confined(proc)
        counts["sandboxes"] += 1
threads = [threading.Thread(target=f) for f in (lines, lines, sandboxes, sandboxes)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
print(counts["lines"], counts["sandboxes"])
"""


@pytest.mark.slow
def test_sandboxes_started_beside_numpy_work_do_not_wedge_the_process(workdir: Path) -> None:
    """What a league server does when a reward check starts while the garage's catalogue
    computes its racing lines: with the rlimits set in a ``preexec_fn``, the racing lines
    stopped for good within a second (OpenBLAS's fork handler deadlocked), so the child never
    finished and ran into the timeout. The counts only show that both kinds of work ran; how
    many racing lines fit in 8 s depends on how busy the machine is (8 on a loaded CI run)."""
    result = subprocess.run(
        [sys.executable, "-c", WEDGE, "8", str(workdir)], capture_output=True, text=True,
        timeout=60, cwd=PROJECT,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    lines, sandboxes = map(int, result.stdout.split())
    assert lines >= 2 and sandboxes >= 2, result.stdout
