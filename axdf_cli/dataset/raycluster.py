"""Ray for ``axdf dataset build --engine ray``: the address checked before anything is
written, signals handled as in every axdf command, and no Ray process left behind.

- ``--address``: ``auto`` (``RAY_ADDRESS``, else the cluster ``ray start`` recorded on this
  machine), ``HOST:PORT`` or ``ray://HOST:PORT`` (Ray Client, which needs ``ray[client]``).
  Anything else is exit 2; a cluster that does not answer a TCP connection within
  :data:`CONNECT_TIMEOUT_S`, a missing Ray Client or no recorded cluster is exit 3, before
  the output folder is touched (``ray.init`` itself would retry for minutes).
- ``ray.init`` installs its own SIGTERM handling (a C++ stack dump, exit 15); ours is put
  back afterwards: SIGINT/SIGTERM end the build with exit 130.
- A local Ray (no ``--address``) is started by this process. A watchdog (a separate small
  process in its own session, so Ctrl-C does not reach it), started just before, notes
  every process this one starts from then on and their descendants (raylet, GCS, the
  dashboard and runtime-env agents, workers: Ray renames some of them, so they are told by
  ancestry, not by name), waits for this process to end however it ends (SIGKILL
  included) or to shut Ray down, then ends whatever of them still runs (SIGTERM, then
  SIGKILL).
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

from axdf_cli.errors import EnvironmentProblem, UsageError

RAY_HINT = "pip install 'ray>=2.9' (or the project's extra: pip install -e '.[ray]')"
CONNECT_TIMEOUT_S = 3.0  # a cluster's GCS port answers at once on a reachable head node
ADDRESS_ALLOWED = "auto, HOST:PORT (a Ray head node's GCS port, e.g. 10.0.0.5:6379) or ray://HOST:PORT (Ray Client)"


def import_ray():
    try:
        import ray
    except ImportError:
        raise EnvironmentProblem("cannot import ray (--engine ray)", RAY_HINT) from None
    return ray


def _host_port(text: str, shown: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536 or \
            any(c.isspace() or c in "/@?#" for c in host):  # a URL (http://...) is not a host
        raise UsageError(f"--address {shown!r}", ADDRESS_ALLOWED)
    return host, int(port)


def _recorded_cluster() -> str | None:
    """The address ``ray start`` recorded on this machine (Ray's own file), if any."""
    for base in {tempfile.gettempdir(), "/tmp"}:
        try:
            text = (Path(base) / "ray" / "ray_current_cluster").read_text().strip()
        except OSError:
            continue
        if text:
            return text
    return None


def check_address(address: str | None) -> str | None:
    """The address ``ray.init`` is given (None: start a local Ray), after checking that
    something answers there. Exit 2 for a malformed address, 3 for an unreachable one."""
    if address is None or address == "local":
        return None
    address = address.strip()
    client = address.startswith("ray://")
    if address == "auto":
        found = os.environ.get("RAY_ADDRESS") or _recorded_cluster()
        if not found:
            raise EnvironmentProblem("--address auto: no running Ray cluster found (no RAY_ADDRESS, and no "
                                     "`ray start` recorded on this machine)",
                                     "start one with `ray start --head`, give its HOST:PORT, or leave --address out "
                                     "to start a local Ray")
        client = found.startswith("ray://")
        target = found[len("ray://"):] if client else found
        shown = f"auto ({found})"
    else:
        target = address[len("ray://"):] if client else address
        shown = address
    host, port = _host_port(target, shown)
    if client:
        try:
            import grpc  # noqa: F401  (Ray Client's transport)
        except ImportError:
            raise EnvironmentProblem(f"--address {shown}: Ray Client (ray://) is not installed",
                                     "pip install 'ray[client]', or give the head node's HOST:PORT") from None
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as e:
        raise EnvironmentProblem(f"--address {shown}: cannot reach a Ray cluster at {host}:{port} "
                                 f"({e.strerror or type(e).__name__}, {CONNECT_TIMEOUT_S:g} s)",
                                 "check the address and that the head node runs (`ray status` there)") from None
    return found if address == "auto" else address


_WATCHDOG = r"""
import os, select, signal, sys, time

def stat(pid):
    with open(f"/proc/{pid}/stat", "rb") as f:
        fields = f.read().rsplit(b")", 1)[1].split()
    return int(fields[1]), int(fields[19])  # parent, start time (clock ticks after boot)

owner, rfd = int(sys.argv[1]), int(sys.argv[2])
me = os.getpid()
since = stat(me)[1]
try:
    pfd = os.pidfd_open(owner)
except (AttributeError, OSError):
    pfd = None
seen = {}  # pid -> start time: the owner's descendants started after this watchdog (Ray's)

def look():
    children = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                parent, start = stat(int(d))
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append((int(d), start))
    stack = [owner] + list(seen)
    while stack:
        for pid, start in children.get(stack.pop(), []):
            if pid != me and start >= since and pid not in seen:
                seen[pid] = start
                stack.append(pid)

while True:
    look()
    ready, _, _ = select.select([rfd] + ([pfd] if pfd is not None else []), [], [], 0.5)
    if rfd in ready and not os.read(rfd, 64):
        break  # the owner closed its end (after ray.shutdown) or died
    if pfd is not None and pfd in ready:
        break
    if pfd is None:
        try:
            os.kill(owner, 0)
        except ProcessLookupError:
            break
look()
time.sleep(1.0)
for sig in (signal.SIGTERM, signal.SIGKILL):
    alive = []
    for pid, start in seen.items():
        try:
            if stat(pid)[1] == start:  # the same process, not a reused pid
                os.kill(pid, sig)
                alive.append(pid)
        except (OSError, IndexError, ValueError):
            pass
    if not alive:
        break
    time.sleep(2.0)
"""


class RayEngine:
    """``with RayEngine(address, jobs) as ray:``: Ray started (or connected) with our signal
    handlers back in place; on leaving, Ray is shut down and a local Ray's processes are gone."""

    def __init__(self, address: str | None, jobs: int):
        self.ray = import_ray()
        self.address = check_address(address)
        self.jobs = jobs
        self.started = False
        self._watchdog = None
        self._wfd = None

    def __enter__(self):
        ray = self.ray
        if not ray.is_initialized():
            handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
            if not self.address:
                self._watch()
            try:
                if self.address:
                    ray.init(address=self.address, log_to_driver=False)
                else:
                    ray.init(num_cpus=self.jobs, include_dashboard=False, log_to_driver=False)
            except (ConnectionError, TimeoutError, RuntimeError, ValueError) as e:
                self._unwatch()
                raise EnvironmentProblem(f"cannot start Ray ({type(e).__name__}: {str(e).splitlines()[0][:200]})",
                                         "check --address, or leave it out to start a local Ray") from None
            except BaseException:
                self._unwatch()
                raise
            finally:
                for s, h in handlers.items():  # Ray's C++ SIGTERM handler dumps a stack and exits 15
                    if h is not None:
                        try:
                            signal.signal(s, h)
                        except ValueError:  # not the main thread
                            pass
            self.started = True
        return ray

    def _watch(self) -> None:
        """Start the watchdog of the processes a local Ray is about to start."""
        if not Path("/proc/self/stat").exists():
            return
        r, w = os.pipe()
        self._watchdog = subprocess.Popen([sys.executable, "-c", _WATCHDOG, str(os.getpid()), str(r)],
                                          pass_fds=(r,), start_new_session=True, stdin=subprocess.DEVNULL,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(r)
        self._wfd = w

    def _unwatch(self) -> None:
        if self._wfd is not None:
            os.close(self._wfd)  # the watchdog ends what is left of Ray's processes, then itself
            self._wfd = None
        if self._watchdog is not None:
            try:
                self._watchdog.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
            self._watchdog = None

    def __exit__(self, *exc) -> None:
        if not self.started:
            return
        try:
            self.ray.shutdown()
        finally:
            self._unwatch()
