"""Ray nodes on this machine as separate processes (``ray start``), for the cluster test.

Each node gets its own ports and its own temporary folder (``<workdir>/<name>``), so that
every process of a node is found by that folder in its command line, and a node is killed
by the PIDs of its own processes: never ``ray stop`` (which stops every Ray process of the
machine, other users' clusters included). Token authentication uses a token of the test's
own (``RAY_AUTH_TOKEN_PATH``), never ``~/.ray``.
"""

from __future__ import annotations

import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

RAY = str(Path(sys.executable).with_name("ray"))

# One node's ports, as offsets from its base port (the head's GCS port is the base itself).
_PORTS = {
    "--node-manager-port": 1,
    "--object-manager-port": 2,
    "--dashboard-agent-listen-port": 3,
    "--dashboard-agent-grpc-port": 4,
    "--runtime-env-agent-port": 5,
    "--metrics-export-port": 6,
}
_HEAD_PORTS = {"--port": 0, "--ray-client-server-port": 7, "--dashboard-port": 8}
_WORKER_PORTS = (10, 29)  # the node's worker processes' port range, offsets
PORTS_PER_NODE = 30


def free_port_base(count: int, start: int = 21000, stop: int = 40000) -> int:
    """The first port of ``count`` consecutive ports nobody listens on, on 127.0.0.1 and on
    every address (a random start, so two tests on one machine rarely try the same)."""
    base = start + secrets.randbelow((stop - start) // count) * count
    for _ in range((stop - start) // count):
        if all(_port_free(port) for port in range(base, base + count)):
            return base
        base = start + (base - start + count) % (stop - start - count)
    raise RuntimeError(f"no {count} consecutive free ports in {start}..{stop}")


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _command_line(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _parent(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return 0


def _start_time(pid: int) -> int:
    """The process's start time (clock ticks after boot; 0 if it is gone): with the PID, it
    names one process, even after its PID is reused."""
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return 0


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not reaped, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


@dataclass
class RayNode:
    """One ``ray start`` node: its name, base port and temporary folder."""

    name: str
    base: int
    temp_dir: Path
    head: bool
    known: dict[int, int] = field(default_factory=dict)  # every PID seen: its start time

    def processes(self) -> list[int]:
        """PIDs of every process of this node: those whose command line names its folder
        (raylet, GCS, agents) and their descendants (Ray's worker processes, which rename
        themselves ``ray::<task>``). Never this process or its parents."""
        marker = str(self.temp_dir)
        mine = {os.getpid(), os.getppid()}
        parents = {}
        found = set()
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) not in mine:
                pid = int(entry.name)
                parents[pid] = _parent(pid)
                if marker in _command_line(pid):
                    found.add(pid)
        grew = True
        while grew:
            more = {pid for pid, parent in parents.items() if parent in found} - found - mine
            grew = bool(more)
            found |= more
        for pid in found:
            self.known.setdefault(pid, _start_time(pid))
        return sorted(found)

    def all_processes(self) -> list[int]:
        """`processes` and every process of this node seen before that still runs (a
        process orphaned by its raylet's death no longer descends from it)."""
        now = set(self.processes())
        seen = {pid for pid, start in self.known.items() if start and _start_time(pid) == start}
        return sorted(now | seen)

    def raylet(self) -> int | None:
        """PID of this node's raylet (the process Ray names ``raylet`` with its folder)."""
        for pid in self.processes():
            words = _command_line(pid).split()
            if words and words[0].endswith("/raylet"):
                return pid
        return None

    def job_processes(self) -> list[int]:
        """PIDs of the Ray worker processes of this node that run a task of the sweep
        (the raylet's children named ``ray::run_job``...; not its agents)."""
        raylet = self.raylet()
        if raylet is None:
            return []
        return [
            pid
            for pid in self.processes()
            if _parent(pid) == raylet
            and _command_line(pid).startswith("ray::")
            and "Agent" not in _command_line(pid)
        ]


@dataclass
class LocalCluster:
    """A head and worker nodes on this machine (`RayNode`), started with ``ray start``."""

    workdir: Path
    base: int = 0
    nodes: list[RayNode] = field(default_factory=list)
    extra_env: dict[str, str] = field(default_factory=dict)  # e.g. Ray's settings

    def __post_init__(self) -> None:
        self.workdir.mkdir(parents=True, exist_ok=True)
        token = self.workdir / "auth_token"
        if not token.exists():
            token.write_text(secrets.token_hex(32))
            token.chmod(0o600)
        if not self.base:
            self.base = free_port_base(PORTS_PER_NODE * 4)

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.base}"

    def env(self) -> dict[str, str]:
        """The environment of every process of the cluster and of its drivers."""
        return {
            **os.environ,
            **self.extra_env,
            "RAY_AUTH_MODE": "token",
            "RAY_AUTH_TOKEN_PATH": str(self.workdir / "auth_token"),
            "RAY_USAGE_STATS_ENABLED": "0",
        }

    def _start(self, name: str, slot: int) -> RayNode:
        head = slot == 0
        node = RayNode(name, self.base + PORTS_PER_NODE * slot, self.workdir / name, head)
        command = [RAY, "start", "--node-ip-address", "127.0.0.1", "--num-cpus", "1"]
        command += ["--temp-dir", str(node.temp_dir), "--disable-usage-stats"]
        command += ["--head", "--include-dashboard", "false"] if head else []
        command += [] if head else ["--address", self.address]
        for option, port in {**_PORTS, **(_HEAD_PORTS if head else {})}.items():
            command += [option, str(node.base + port)]
        command += ["--min-worker-port", str(node.base + _WORKER_PORTS[0])]
        command += ["--max-worker-port", str(node.base + _WORKER_PORTS[1])]
        log = self.workdir / f"ray-start-{name}.log"
        with open(log, "a") as out:
            done = subprocess.run(command, env=self.env(), stdout=out, stderr=out, timeout=180)
        if done.returncode != 0:
            raise RuntimeError(f"ray start of node {name} failed (see {log})")
        self.nodes.append(node)
        node.processes()  # remembered, to be stopped even once orphaned
        return node

    def start_head(self) -> RayNode:
        return self._start("head", 0)

    def start_worker(self, name: str = "worker", slot: int = 1) -> RayNode:
        """A worker node; ``slot`` (1 to 3) chooses its ports."""
        return self._start(name, slot)

    def node(self, name: str) -> RayNode:
        return next(n for n in self.nodes if n.name == name)

    def alive_nodes(self, timeout: float = 60.0) -> int:
        """Nodes the cluster's GCS counts alive (asked by a short-lived driver)."""
        code = (
            f"import ray; ray.init(address={self.address!r}, log_to_driver=False); "
            "print(sum(1 for n in ray.nodes() if n['Alive']))"
        )
        done = subprocess.run(
            [sys.executable, "-c", code],
            env=self.env(),
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        if done.returncode != 0:
            raise RuntimeError(f"cannot reach the cluster at {self.address}: {done.stderr[-500:]}")
        return int(done.stdout.strip().splitlines()[-1])

    def kill(self, name: str, raylet_only: bool = False) -> list[int]:
        """SIGKILL a node: its raylet alone (the node is lost; what its other processes
        do then is Ray's to decide) or every process of it. Returns the PIDs killed."""
        node = self.node(name)
        pids = [node.raylet()] if raylet_only else node.all_processes()
        killed = []
        for pid in pids:
            if pid is None:
                continue
            try:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            except ProcessLookupError:
                pass
        return killed

    def signal(self, name: str, number: int, pids: list[int] | None = None) -> list[int]:
        """Send signal ``number`` to every process of a node (or to ``pids``); the PIDs."""
        pids = self.node(name).all_processes() if pids is None else pids
        for pid in pids:
            try:
                os.kill(pid, number)
            except ProcessLookupError:
                pass
        return pids

    def stop(self) -> None:
        """SIGKILL every process of every node (this cluster's processes only)."""
        for node in self.nodes:
            for pid in node.all_processes():
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        deadline = time.time() + 30
        while time.time() < deadline and any(
            alive(pid) for n in self.nodes for pid in n.all_processes()
        ):
            time.sleep(0.2)
        self.nodes = []
