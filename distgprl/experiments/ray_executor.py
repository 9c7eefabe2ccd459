"""The sweep's ``ray`` executor: every job a Ray task, on a local Ray instance or a cluster
(``--address``), with the same job function as the local executor (`sweep.run_job`).

Faults (measured with `scripts/cluster_test.py`, a head and a worker node on one machine;
docs/DESIGN.md, "Executors"):

- **A worker node is lost** (its raylet killed): Ray's worker processes on that node exit
  within about 2 s (they watch their raylet), which releases the run lock (``.lock``,
  `run_lock`) of the run they trained; the sweep learns of it at once (``NodeDiedError``).
  The task is then retried on a live node (`MAX_RETRIES`), where it resumes the run from its
  last checkpoint: a sweep job is idempotent (a finished run is skipped, a partial one
  resumed, a locked one left alone), so running it again is safe.
- **A worker node hangs** (every process of it stopped: a hang, a network partition): the
  head declares it dead after its health check fails, but Ray starts the retry only once
  the hung process's connection closes: when the node goes on again, its raylet, told it
  is dead, exits and the process with it, then the retry resumes the run. A node that never
  comes back keeps its task waiting (Ctrl-C and a re-run resume it).
- **A retry cannot collide with the lost node's process**: the run lock is an exclusive
  ``flock`` on the shared results folder. A retry that finds it still held (the lost node's
  process not yet gone: on a real network, a node cut off from its head only stops its
  processes once its raylet gives up on the head, Ray's ``gcs_rpc_server_reconnect_timeout_s``,
  60 s) waits up to `LOCK_WAIT_S` for it (`_wait_for_lock`), then reports the run ``busy``
  instead of training it a second time. This needs a shared file system whose ``flock``
  holds across nodes (NFSv4, Lustre mounted with ``flock``, GPFS, BeeGFS; not Lustre's
  ``localflock``): docs/guides/slurm.md.
- **The head is lost**: every task's owner is the sweep, and the sweep's Ray connection
  goes through the head, so nothing can be retried. The sweep notices within
  `HEAD_LOST_AFTER_S` (`_head_reachable`) and stops with `ClusterLostError`: one line,
  exit code 4 (`distgprl sweep`); restarting the cluster and re-running the same command
  resumes the unfinished runs from their checkpoints.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Generator
from dataclasses import replace
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.experiments.jobs import Job
from distgprl.io import is_locked
from distgprl.schema import run_dir

MAX_RETRIES = 2
"""Retries of a task whose worker process or node died (Ray's ``max_retries``: system
failures only; an exception in a job is caught by `run_job` and recorded, never retried).
A retry resumes the run from its last checkpoint, so it costs at most the steps since then;
two retries let a run outlive two node losses, and bound what a job that crashes its
process every time (a native crash, the OOM killer) costs to three attempts."""

LOCK_WAIT_S = 90.0
"""How long a task waits for a run lock another process holds before reporting the run
``busy``: longer than a lost node's processes live on (at most Ray's 60 s GCS reconnect
timeout, then about 1 s for its worker processes to follow their raylet)."""

HEAD_LOST_AFTER_S = 10.0
"""How long the head's GCS port must refuse connections before the sweep gives up on the
cluster (a restarting network blip is shorter; Ray itself gives up after 60 s, with a
traceback)."""

CLUSTER_LOST_EXIT = 4
"""Exit code of `distgprl sweep` when its Ray cluster was lost (`ClusterLostError`)."""

POLL_S = 1.0
"""Seconds between the sweep's checks for finished tasks and for its head."""


class ClusterLostError(UserInputError):
    """The Ray cluster's head stopped answering while a sweep ran on it.

    Attributes:
        address: the head's GCS address.
        unfinished: the jobs without a result (some may still finish: a worker node goes
            on with its task until its raylet gives up on the head).
    """

    def __init__(self, address: str, unfinished: list[Job]):
        runs = "1 run" if len(unfinished) == 1 else f"{len(unfinished)} runs"
        super().__init__(
            f"sweep: the ray cluster at {address} was lost (its head does not answer) before "
            f"{runs} reported back: restart the cluster and re-run the same command (finished "
            "runs are skipped, the others resume from their checkpoints)"
        )
        self.address = address
        self.unfinished = unfinished


def _host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``host:port`` address; None for other forms (``auto``,
    ``ray://...``), which are left to Ray."""
    host, _, port = address.rpartition(":")
    if not host or "/" in address or not port.isdigit():
        return None
    return host.strip("[]"), int(port)


def _head_reachable(host_port: tuple[str, int], timeout: float = 2.0) -> bool:
    """Whether the head's GCS port accepts a TCP connection."""
    try:
        with socket.create_connection(host_port, timeout=timeout):
            return True
    except OSError:
        return False


def _wait_for_lock(job: Job, wait_s: float, poll_s: float = 1.0) -> None:
    """Wait (at most ``wait_s``) while another process holds the job's run lock: the
    process of a lost node that has not noticed yet (module docstring)."""
    folder = run_dir(job.root, job.preset, job.task, job.method, job.seed)
    deadline = time.monotonic() + wait_s
    while is_locked(folder) and time.monotonic() < deadline:
        time.sleep(poll_s)


def _connect(ray, address: str | None, workers: int) -> bool:
    """Connect to the cluster at ``address`` (or start a local instance); True if this
    call did (so the sweep shuts it down). A head that does not answer is one line."""
    if ray.is_initialized():
        return False
    if not address:
        ray.init(num_cpus=max(workers, 1), include_dashboard=False, log_to_driver=False)
        return True
    host_port = _host_port(address)
    if host_port is not None and not _head_reachable(host_port):
        raise UserInputError(
            f"no ray cluster answers at {address}: start one (`ray start --head --port "
            f"{host_port[1]}`) or pass the address `ray start --head` printed"
        )
    try:
        ray.init(address=address, log_to_driver=False)
    except (ConnectionError, RuntimeError) as error:
        raise UserInputError(
            f"cannot connect to the ray cluster at {address}: {_why_not_connected(error)}"
        ) from None
    return True


def _why_not_connected(error: BaseException) -> str:
    """One line for a failed ``ray.init``: its message's first line, or, for a token that
    does not match the cluster's (Ray wraps that error's text into the one it raises), what
    to do about it."""
    causes = [error]
    while causes[-1].__cause__ is not None and len(causes) < 10:
        causes.append(causes[-1].__cause__)
    if any("InvalidAuthToken" in str(cause) or "Authentication" in str(cause) for cause in causes):
        return (
            "its authentication token is missing or wrong here (set RAY_AUTH_MODE=token and "
            "RAY_AUTH_TOKEN_PATH to the token file the cluster was started with)"
        )
    return (str(error).splitlines() or [type(error).__name__])[0]


def _describe_lost(error: Exception) -> str:
    """One line for a task Ray gave up on (its retries spent)."""
    name = type(error).__name__
    if name == "NodeDiedError":
        what = "the Ray node running it was lost"
    elif name in ("WorkerCrashedError", "OutOfMemoryError"):
        what = "its Ray worker process died"
    else:
        what = (str(error).splitlines() or [""])[0]
    return (
        f"{name}: {what} (retried {MAX_RETRIES} times); its last checkpoint stays for "
        "the next sweep to resume"
    )


def run_on_ray(
    jobs: list[Job],
    workers: int,
    address: str | None,
    job_function: Callable,
    record_failure: Callable,
) -> Generator:
    """Run ``jobs`` as Ray tasks (``job_function``: `sweep.run_job`, looked up by the caller
    so that a replaced one is the one sent) and yield their `JobResult`s as they finish; a
    task Ray gave up on is recorded with ``record_failure`` (its ``error.json``)."""
    try:
        import ray
    except ImportError:
        raise UserInputError(
            "the ray executor needs the optional extra: pip install -e '.[ray]' (in the project)"
        ) from None
    started_here = _connect(ray, address, workers)
    head = None
    if address:
        head = _host_port(ray.get_runtime_context().gcs_address)
    lock_wait_s = LOCK_WAIT_S

    def on_node(job: Job):  # a closure: pickled by value, with the job function it calls
        _wait_for_lock(job, lock_wait_s)
        return job_function(job)

    lost = False
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(on_node)
        # Workers resolve the results root on their own machines: pass it absolute (a
        # cluster's nodes must share this path, e.g. a network file system).
        submitted = {
            remote.remote(replace(job, root=str(Path(job.root).resolve()))): job for job in jobs
        }
        pending = list(submitted)
        unreachable_since = None
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
                for ref in done:
                    job = submitted[ref]
                    try:
                        result = ray.get(ref)
                    except ray.exceptions.RayError as error:  # retries spent: lost
                        yield record_failure(job, _describe_lost(error), str(error), 0.0)
                        continue
                    yield replace(result, job=job)
                if head is None or not pending:
                    continue
                if _head_reachable(head):
                    unreachable_since = None
                elif unreachable_since is None:
                    unreachable_since = time.monotonic()
                elif time.monotonic() - unreachable_since >= HEAD_LOST_AFTER_S:
                    lost = True
                    raise ClusterLostError(address or "", [submitted[ref] for ref in pending])
        except BaseException:
            if not lost:
                for ref in pending:  # queued: dropped; running: KeyboardInterrupt, as locally
                    ray.cancel(ref)
            raise
    finally:
        if started_here and not lost:  # without its head, Ray cannot shut down in order
            ray.shutdown()
