"""Run a racer's training code (their reward function, run by our training program) in a
child process confined by bubblewrap (``/usr/bin/bwrap``) and rlimits; never in a league
process.

The child gets a root of its own: read-only ``/usr`` (and ``/bin``, ``/lib*``, ``/sbin``),
``/etc/passwd``, ``/etc/group``, ``/etc/ld.so.cache`` and ``/etc/localtime``, the Python
installation, the virtualenv and the code packages (:func:`readable_paths`); a private
``/proc``, ``/dev``, and small tmpfs ``/tmp`` and ``/dev/shm``; and one writable folder, the
job's ``workdir`` (at its own path, and its cwd and ``HOME``). It has new PID, network
(loopback only), IPC, UTS and cgroup namespaces, an emptied environment, and the rlimits of
:class:`ConfinementLimits` on each of its processes. bwrap itself starts with ``PATH``
alone in its environment: it is PID 1 in the sandbox, and ``/proc/1/environ`` shows no
secret of the caller.

Users. A caller that is not root runs bwrap unprivileged, in a new user namespace, as
itself: ``RLIMIT_NPROC`` then counts every process of the caller's user, so such a trainer
should run as a user of its own. The kernel does not apply ``RLIMIT_NPROC`` to root (nor to
root mapped into a user namespace), so a root caller runs the code as :data:`SANDBOX_UID`
instead: bwrap runs privileged (no user namespace; it builds the mounts as root, so the
Python installation may live under ``/root`` and the workdir under a private folder), keeps
only ``CAP_SETUID``/``CAP_SETGID``, and a tiny launcher inside drops to ``SANDBOX_UID`` (no
groups, no capabilities, ``no_new_privs``) before it execs the command. The workdir is
chowned to ``SANDBOX_UID`` first. ``RLIMIT_NPROC`` counts all processes of that uid, so
sandboxes running at the same time share it.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

MiB = 1024 * 1024
BWRAP = "/usr/bin/bwrap"
SANDBOX_UID = 65534
"""The unprivileged uid (and gid) the sandbox runs as when the caller is root."""
CODE_PACKAGES = ("agents", "arena", "tracks", "submissions")
"""The project's packages a confined Python may import (each mounted alone)."""
BWRAP_ENV = {"PATH": "/usr/bin:/bin"}
"""The whole environment of the bwrap process (PID 1 inside)."""
_SYSTEM_DIRS = ("/bin", "/lib", "/lib32", "/lib64", "/libx32", "/sbin")
_ETC_FILES = ("/etc/ld.so.cache", "/etc/localtime", "/etc/passwd", "/etc/group")
_PR_SET_PDEATHSIG = 1
_PROBE_SECONDS = 30.0
_DROP = (
    "import os,sys;u,g=int(sys.argv[1]),int(sys.argv[2]);os.setgroups([]);"
    "os.setresgid(g,g,g);os.setresuid(u,u,u);"
    "os.getresuid()==(u,u,u) and os.getresgid()==(g,g,g) or sys.exit('cannot drop root');"
    "os.chdir(sys.argv[3]);os.environ['PWD']=sys.argv[3];os.execvp(sys.argv[4],sys.argv[4:])"
)
"""Launcher run inside a root-started sandbox: drop to the sandbox uid, enter the workdir
(root without capabilities may not: it is the sandbox uid's), exec the command."""

_LIMIT = f"""
import ctypes, os, resource as r, signal, sys
names = (r.RLIMIT_AS, r.RLIMIT_CPU, r.RLIMIT_NPROC, r.RLIMIT_FSIZE, r.RLIMIT_NOFILE, r.RLIMIT_CORE)
for name, value in zip(names, sys.argv[1:7]):
    r.setrlimit(name, (int(value), int(value)))
try:
    ctypes.CDLL(None).prctl({_PR_SET_PDEATHSIG}, signal.SIGKILL)
except (OSError, AttributeError):  # not Linux: no death with the parent
    pass
if sys.argv[7]:  # the caller's LC_CTYPE, which Python's locale coercion may have changed
    os.environ["LC_CTYPE"] = sys.argv[7]
else:
    os.environ.pop("LC_CTYPE", None)
os.execvp(sys.argv[8], sys.argv[8:])
"""
"""Launcher of :func:`limited`: address space, CPU seconds, processes, file size, open
files and core size from its arguments, killed when its parent dies, then the command in
the caller's environment."""


@dataclass(frozen=True)
class ConfinementLimits:
    """Limits of each process in the sandbox (rlimits), and the size of its ``/tmp``."""

    memory_mb: int = 4096  # RLIMIT_AS of each process
    cpu_seconds: int = 7200  # RLIMIT_CPU of each process
    processes: int = 1024  # RLIMIT_NPROC (threads count too)
    file_mb: int = 1024  # RLIMIT_FSIZE: largest file it may write
    open_files: int = 1024  # RLIMIT_NOFILE
    tmp_mb: int = 256  # size of its private /tmp (tmpfs); /dev/shm gets as much again


class SandboxUnavailable(RuntimeError):
    """This host cannot confine a process (message says why and what to install)."""


def _nonnested(paths: Iterable[Path]) -> list[Path]:
    """``paths`` resolved, without duplicates or paths inside another one, in order."""
    resolved = list(dict.fromkeys(Path(p).resolve() for p in paths))
    return [p for p in resolved if not any(o != p and o in p.parents for o in resolved)]


def _package_dir(name: str) -> Path | None:
    """The directory of the top-level package ``name`` (not imported), or None."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    return Path(locations[0]).resolve() if locations else None


def _project_root() -> Path:
    """The folder holding the code packages (the parent of ``agents``): ``PYTHONPATH``."""
    agents = _package_dir("agents")
    return agents.parent if agents is not None else Path(__file__).resolve().parents[2]


def readable_paths() -> list[Path]:
    """What a confined Python needs to read: the interpreter's install (sys.base_prefix),
    the virtualenv (sys.prefix), and the project's code packages `agents`, `arena`,
    `tracks`, `submissions` (each package directory alone, never the project root, so a data
    directory or .env beside the code stays invisible). Symlinks resolved, without
    duplicates or paths nested in others."""
    packages = [_package_dir(name) for name in CODE_PACKAGES]
    return _nonnested(
        [Path(sys.base_prefix), Path(sys.prefix), *(p for p in packages if p is not None)]
    )


def _run_as(uid: int | None) -> int:
    """The uid confined code runs as: ``uid``, else the sandbox uid for root, else the
    caller's own."""
    if uid is not None:
        return uid
    return SANDBOX_UID if os.geteuid() == 0 else os.geteuid()


@functools.cache
def _bwrap_options() -> frozenset[str]:
    """The options this host's bwrap knows (from ``bwrap --help``)."""
    try:
        text = subprocess.run(
            [BWRAP, "--help"], capture_output=True, text=True, env=BWRAP_ENV, timeout=10
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return frozenset()
    return frozenset(word for word in text.split() if word.startswith("--"))


def _tmpfs(dest: str, size_mb: int) -> list[str]:
    """Mount a fresh tmpfs on ``dest``, writable by all (sticky), of ``size_mb`` where
    this bwrap can limit it (``--size``, bwrap 0.8)."""
    options = _bwrap_options()
    args = ["--perms", "1777"] if "--perms" in options else []
    if "--size" in options:
        args += ["--size", str(size_mb * MiB)]
    return [*args, "--tmpfs", dest]


def _bind(option: str, path: Path) -> list[str]:
    """Bind ``path`` at its own path, its missing parents made 0755 first (bwrap makes a
    bind's parents 0700: unreadable to a sandbox uid other than bwrap's)."""
    parent = ["--dir", str(path.parent)] if path.parent != Path("/") else []
    return [*parent, option, str(path), str(path)]


def _environment(workdir: Path, env: dict[str, str] | None) -> dict[str, str]:
    """The whole environment of the confined command."""
    return {
        "PATH": f"{Path(sys.prefix) / 'bin'}:/usr/bin:/bin",
        "HOME": str(workdir),
        "PYTHONDONTWRITEBYTECODE": "1",
        "LANG": "C.UTF-8",
        "PYTHONPATH": str(_project_root()),
        **(env or {}),
    }


def _bwrap_argv(
    argv: Sequence[str],
    workdir: Path,
    limits: ConfinementLimits,
    env: dict[str, str] | None,
    extra_readable: Sequence[Path],
    uid: int,
) -> list[str]:
    """The bwrap command line that runs ``argv`` confined, as ``uid``."""
    privileged = os.geteuid() == 0
    args = [BWRAP]
    if privileged:  # no user namespace: the code must run as a real uid other than root
        args += ["--unshare-ipc", "--unshare-pid", "--unshare-net", "--unshare-uts"]
        args += ["--unshare-cgroup-try", "--cap-drop", "ALL"]
        args += ["--cap-add", "CAP_SETUID", "--cap-add", "CAP_SETGID"]
    else:
        args += ["--unshare-all"]
    args += ["--die-with-parent", "--new-session", "--clearenv"]
    for name, value in _environment(workdir, env).items():
        args += ["--setenv", name, value]
    # fresh file systems first: a bind below /tmp (a workdir there) must land on top
    args += ["--proc", "/proc", "--dev", "/dev"]
    args += _tmpfs("/tmp", limits.tmp_mb) + _tmpfs("/dev/shm", limits.tmp_mb)
    args += ["--ro-bind", "/usr", "/usr"]
    for name in _SYSTEM_DIRS:
        path = Path(name)
        if path.is_symlink():
            args += ["--symlink", os.readlink(path), name]
        elif path.exists():
            args += ["--ro-bind", name, name]
    for name in _ETC_FILES:
        if os.path.exists(name):
            args += _bind("--ro-bind", Path(name))
    usr = Path("/usr")
    readable = [p for p in readable_paths() if p != usr and usr not in p.parents]
    for path in readable:
        args += _bind("--ro-bind", path)
    args += _bind("--bind", workdir)
    for path in _nonnested(extra_readable):
        if not any(p == path or p in path.parents for p in readable):
            args += _bind("--ro-bind", path)
    # the root and /dev tmpfs read-only: nothing but /tmp, /dev/shm and the workdir to fill
    args += ["--remount-ro", "/dev", "--remount-ro", "/"]
    if privileged and uid != 0:
        args += ["--chdir", "/", "--", sys.executable, "-I", "-S", "-c", _DROP]
        return [*args, str(uid), str(uid), str(workdir), *argv]
    return [*args, "--chdir", str(workdir), "--", *argv]


def limited(
    argv: Sequence[str], limits: ConfinementLimits, env: dict[str, str] | None = None
) -> list[str]:
    """``argv`` behind a tiny launcher that sets the rlimits (inherited by all it starts) and
    death with the parent, then execs it. ``env`` is the environment the launcher is started
    with (by default the caller's), which the command gets unchanged.

    Not a ``preexec_fn``: that makes Python fork the whole threaded caller and run Python in
    the child, and the fork waits in the handlers libraries register for it. OpenBLAS's
    deadlocked a league server whose other thread was in a numpy solve (a race line for
    the garage's catalogue). Without one, the child is spawned with ``vfork`` and runs no
    code of the caller's.
    """
    values = (
        limits.memory_mb * MiB,
        limits.cpu_seconds,
        limits.processes,
        limits.file_mb * MiB,
        limits.open_files,
        0,
    )
    locale = (os.environ if env is None else env).get("LC_CTYPE", "")
    return [sys.executable, "-I", "-S", "-c", _LIMIT, *map(str, values), locale, *argv]


def _give_to(workdir: Path, uid: int) -> None:
    """Chown ``workdir`` and all in it to ``uid`` (never following a symlink a previous run
    may have left there)."""
    os.chown(workdir, uid, uid, follow_symlinks=False)
    for root, dirs, files in os.walk(workdir):
        for name in dirs + files:
            os.chown(os.path.join(root, name), uid, uid, follow_symlinks=False)


def _start(
    argv: Sequence[str],
    workdir: Path,
    limits: ConfinementLimits,
    uid: int,
    *,
    stdout: int | None = subprocess.PIPE,
    stderr: int | None = subprocess.STDOUT,
    env: dict[str, str] | None = None,
    extra_readable: Sequence[Path] = (),
) -> subprocess.Popen[bytes]:
    """Start ``argv`` confined as ``uid``, without asking :func:`probe` first."""
    workdir = Path(workdir).resolve(strict=True)
    if not workdir.is_dir():
        raise NotADirectoryError(f"the sandbox workdir {workdir} is not a directory")
    if os.geteuid() == 0 and uid != 0:
        _give_to(workdir, uid)
    return subprocess.Popen(
        limited(
            _bwrap_argv(argv, workdir, limits, env, [Path(p) for p in extra_readable], uid),
            limits,
            BWRAP_ENV,
        ),
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=stderr,
        env=BWRAP_ENV,
        cwd="/",
        close_fds=True,
        start_new_session=True,
    )


_PROBE_CODE = """
import importlib.util, os, sys
for path in sys.argv[1:]:
    os.listdir(path)
for name in {packages!r}:
    assert importlib.util.find_spec(name) is not None, f"cannot import {{name}}"
with open("probe", "w") as handle:
    handle.write("ok")
print("confined-ok", os.getuid())
"""


def _reason_from(output: str, uid: int) -> str:
    """One sentence for a failed probe run, from its output."""
    lines = [line.strip() for line in output.strip().splitlines() if line.strip()]
    last = lines[-1] if lines else "no output"
    if "namespace" in output or "uid map" in output or "Operation not permitted" in output:
        return (
            f"bubblewrap cannot create namespaces here ({last}): allow unprivileged user "
            "namespaces (sysctl kernel.unprivileged_userns_clone=1, user.max_user_namespaces"
            " > 0, or the AppArmor userns restriction lifted for bwrap), or run as root"
        )
    if "Permission denied" in output or "PermissionError" in output:
        return (
            f"uid {uid} cannot read what a confined Python needs ({last}): make the Python "
            "installation, the virtualenv and the code packages readable by it"
        )
    return f"a confined Python did not start ({last})"


@functools.cache
def _probe(uid: int) -> str | None:
    if not os.access(BWRAP, os.X_OK):
        return f"{BWRAP} is missing: install bubblewrap (apt install bubblewrap)"
    if os.geteuid() != 0 and uid != os.geteuid():
        return f"only root can run the sandbox as another user (uid {uid})"
    if uid == 0:
        return "the sandbox cannot run as root: the kernel does not limit root's processes"
    code = _PROBE_CODE.format(packages=CODE_PACKAGES)
    paths = [str(p) for p in readable_paths()]
    workdir = Path(tempfile.mkdtemp(prefix="slipstream-probe-"))
    try:
        limits = ConfinementLimits(memory_mb=1024, cpu_seconds=30, processes=1024, tmp_mb=1)
        try:
            proc = _start([sys.executable, "-c", code, *paths], workdir, limits, uid)
        except OSError as exc:
            return f"bubblewrap could not be started ({exc})"
        try:
            output, _ = proc.communicate(timeout=_PROBE_SECONDS)
        except subprocess.TimeoutExpired:
            return f"a confined Python did not finish in {_PROBE_SECONDS:g} s"
        finally:
            kill_confined(proc)
        text = output.decode(errors="replace")
        if proc.returncode == 0 and "confined-ok" in text and (workdir / "probe").exists():
            return None
        return _reason_from(text, uid)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def probe(uid: int | None = None) -> str | None:
    """None when this host can run a confined Python (bwrap present, namespaces allowed,
    the sandbox uid can read :func:`readable_paths`), else the reason in one sentence.
    ``uid``: the uid to check for (default: :data:`SANDBOX_UID` for root, else the
    caller's). Runs a confined Python once; cached per process."""
    return _probe(_run_as(uid))


def confined_popen(
    argv: list[str],
    workdir: Path,
    limits: ConfinementLimits = ConfinementLimits(),
    *,
    stdout: int | None = subprocess.PIPE,
    stderr: int | None = subprocess.STDOUT,
    env: dict[str, str] | None = None,
    extra_readable: Sequence[Path] = (),
) -> subprocess.Popen[bytes]:
    """Start argv confined; workdir is the only writable directory it sees (mounted at the
    same path, and its cwd). ``env`` is added to the confined environment, and
    ``extra_readable`` paths are mounted read-only. Raises SandboxUnavailable when probe()
    fails. Stop it with :func:`kill_confined`."""
    reason = probe()
    if reason is not None:
        raise SandboxUnavailable(f"cannot sandbox: {reason}")
    return _start(
        argv,
        workdir,
        limits,
        _run_as(None),
        stdout=stdout,
        stderr=stderr,
        env=env,
        extra_readable=extra_readable,
    )


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (bwrap's: the sandbox's PID 1)."""
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except (OSError, ValueError):
        pass
    found = []
    for entry in Path("/proc").iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):
            if entry.name.isdigit():
                stat = (entry / "stat").read_text()
                if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
    return found


def _gone(pid: int) -> bool:
    """Whether ``pid`` has exited (gone, or a zombie: its PID namespace is empty then)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def kill_confined(proc: subprocess.Popen) -> None:
    """SIGKILL the sandbox and everything in it (killing bwrap's pid-namespace init kills
    the namespace), then reap."""
    if proc.poll() is not None:
        return  # bwrap exits only after its PID 1, and the namespace went with it
    inits = _children(proc.pid)
    for pid in inits:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=5)  # bwrap exits once it has reaped its PID 1
    with contextlib.suppress(ProcessLookupError, PermissionError):
        proc.kill()  # a no-op once it has been reaped
    proc.wait()
    deadline = time.monotonic() + 5
    while inits and not all(_gone(pid) for pid in inits) and time.monotonic() < deadline:
        time.sleep(0.01)
