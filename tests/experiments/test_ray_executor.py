"""The ray executor's handling of faults (`distgprl.experiments.ray_executor`), without a
cluster: a head nobody answers at, a run lock a lost node's process still holds, a head
lost mid-sweep (a stand-in for Ray whose tasks never finish), a task Ray gave up on. The
same faults on a real two-node cluster: `make test-cluster` (`scripts/cluster_test.py`)."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

from distgprl.experiments import ray_executor, sweep
from distgprl.experiments.run_control import describe_resume
from distgprl.io import is_locked
from distgprl.schema import read_json, run_dir, write_json


def closed_port() -> int:
    """A port nobody listens on (bound, then released)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_addresses_are_split_into_host_and_port():
    assert ray_executor._host_port("127.0.0.1:6379") == ("127.0.0.1", 6379)
    assert ray_executor._host_port("[::1]:6379") == ("::1", 6379)
    assert ray_executor._host_port("node01.cluster:26379") == ("node01.cluster", 26379)
    for left_to_ray in ("auto", "ray://node01:10001", "node01", "node01:port"):
        assert ray_executor._host_port(left_to_ray) is None


def test_a_sweep_on_an_address_nobody_answers_exits_2_with_one_line(tmp_path):
    address = f"127.0.0.1:{closed_port()}"
    command = [sys.executable, "-m", "distgprl.cli", "sweep", "--preset", "ci"]
    command += ["--methods", "demo", "--tasks", "dcp", "--seeds", "0", "--root", str(tmp_path)]
    command += ["--executor", "ray", "--address", address]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"error: no ray cluster answers at {address}: start one (`ray start --head --port "
        f"{address.rsplit(':', 1)[1]}`) or pass the address `ray start --head` printed"
    ]
    assert not (tmp_path / "ci").exists()


def hold_lock(folder: Path, seconds: float) -> subprocess.Popen:
    """A process that holds the run folder's lock for ``seconds`` (as a lost node's
    process that has not noticed yet)."""
    code = (
        "import sys, time; from pathlib import Path; "
        "from distgprl.experiments.run_control import run_lock\n"
        "with run_lock(Path(sys.argv[1])):\n"
        "    print('locked', flush=True); time.sleep(float(sys.argv[2]))"
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", code, str(folder), str(seconds)], stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
    return holder


def test_a_task_waits_for_a_lock_held_by_a_lost_nodes_process(tmp_path):
    """Until the holder lets go, or at most the wait given (then `run_job` says busy)."""
    [job] = sweep.plan_jobs("ci", ["gprl"], ["dcp"], [0], root=tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "gprl", 0)
    holder = hold_lock(folder, 1.5)
    try:
        start = time.monotonic()
        ray_executor._wait_for_lock(job, wait_s=60, poll_s=0.1)
        assert 0.5 < time.monotonic() - start < 30 and not is_locked(folder)
    finally:
        holder.wait()
    holder = hold_lock(folder, 60)
    try:
        start = time.monotonic()
        ray_executor._wait_for_lock(job, wait_s=1.0, poll_s=0.1)
        assert 1.0 <= time.monotonic() - start < 10 and is_locked(folder)
        result = sweep.run_job(job)
        assert (result.status, result.error) == ("busy", "another process is training this run")
    finally:
        holder.kill()
        holder.wait()


class FakeRay(types.SimpleNamespace):
    """Stands in for `ray` in `run_on_ray`: tasks that never finish (``finish`` maps the
    jobs that do to their result or error), a cluster at ``gcs_address``."""

    class RayError(Exception):
        pass

    class NodeDiedError(RayError):
        pass

    def __init__(self, finish: dict):
        super().__init__(calls=[], finish=finish)
        self.exceptions = types.SimpleNamespace(RayError=FakeRay.RayError)

    def is_initialized(self):
        return False

    def init(self, **kwargs):
        self.calls.append(("init", kwargs))

    def get_runtime_context(self):
        return types.SimpleNamespace(gcs_address="192.0.2.7:26379")

    def remote(self, **options):
        self.calls.append(("remote", options))
        return lambda function: types.SimpleNamespace(remote=lambda job: job)

    def wait(self, pending, num_returns, timeout):
        done = [job for job in pending if job.method in self.finish][:num_returns]
        if not done:
            time.sleep(timeout)
        return done, [job for job in pending if job not in done]

    def get(self, job):
        outcome = self.finish[job.method]
        if isinstance(outcome, Exception):
            raise outcome
        return outcome

    def cancel(self, ref):
        self.calls.append(("cancel", ref))

    def shutdown(self):
        self.calls.append(("shutdown", None))


def run_with_fake_ray(monkeypatch, tmp_path, finish, head_answers: bool):
    fake = FakeRay(finish)
    monkeypatch.setitem(sys.modules, "ray", fake)
    monkeypatch.setattr(ray_executor, "POLL_S", 0.05)
    monkeypatch.setattr(ray_executor, "HEAD_LOST_AFTER_S", 0.3)
    answers = iter([True])  # it answers when the sweep connects, then ``head_answers``
    monkeypatch.setattr(ray_executor, "_head_reachable", lambda hp: next(answers, head_answers))
    jobs = sweep.plan_jobs("ci", ["gprl", "gprl-d", "gprl-h"], ["dcp"], [0], root=tmp_path)
    results = []
    try:
        for result in ray_executor.run_on_ray(
            jobs, 2, "127.0.0.1:26379", sweep.run_job, sweep.record_failure
        ):
            results.append(result)
    except ray_executor.ClusterLostError as lost:
        return fake, results, lost
    return fake, results, None


def test_a_lost_head_stops_the_sweep_with_the_runs_that_did_not_report(monkeypatch, tmp_path):
    done = sweep.JobResult(sweep.plan_jobs("ci", ["gprl"], ["dcp"], [0], tmp_path)[0], "done", 1)
    fake, results, lost = run_with_fake_ray(monkeypatch, tmp_path, {"gprl": done}, False)
    assert [r.status for r in results] == ["done"]
    assert lost is not None and [job.method for job in lost.unfinished] == ["gprl-d", "gprl-h"]
    assert str(lost) == (
        "sweep: the ray cluster at 127.0.0.1:26379 was lost (its head does not answer) before "
        "2 runs reported back: restart the cluster and re-run the same command (finished runs "
        "are skipped, the others resume from their checkpoints)"
    )
    assert ("remote", {"num_cpus": 1, "max_retries": ray_executor.MAX_RETRIES}) in fake.calls
    # without its head Ray can neither cancel nor shut down: neither is tried
    assert not [call for call in fake.calls if call[0] in ("cancel", "shutdown")]


def test_a_task_ray_gave_up_on_is_recorded_and_the_others_go_on(monkeypatch, tmp_path):
    jobs = sweep.plan_jobs("ci", ["gprl", "gprl-d", "gprl-h"], ["dcp"], [0], root=tmp_path)
    finish = {
        "gprl": FakeRay.NodeDiedError("Task failed because the node it was running on is dead"),
        "gprl-d": sweep.JobResult(jobs[1], "done", 1.0),
        "gprl-h": sweep.JobResult(jobs[2], "done", 1.0),
    }
    fake, results, lost = run_with_fake_ray(monkeypatch, tmp_path, finish, True)
    assert lost is None
    assert sorted((r.job.method, r.status) for r in results) == [
        ("gprl", "failed"),
        ("gprl-d", "done"),
        ("gprl-h", "done"),
    ]
    error = read_json(run_dir(tmp_path, "ci", "dcp", "gprl", 0) / "error.json")["error"]
    assert error == (
        f"NodeDiedError: the Ray node running it was lost (retried {ray_executor.MAX_RETRIES} "
        "times); its last checkpoint stays for the next sweep to resume"
    )
    assert fake.calls[-1] == ("shutdown", None)


@pytest.mark.parametrize(
    ("reached", "resumes", "expected"),
    [
        (0, [], ""),
        (120, [{"step": 121, "exact": True}], "resumed from its checkpoint of step 121"),
        (120, [{"step": 0, "exact": False}], "restarted from step 0 (it had reached step 120)"),
    ],
)
def test_a_sweep_says_where_a_run_it_continued_was_resumed(tmp_path, reached, resumes, expected):
    write_json(tmp_path / "done.json", {"steps": 240, "resumes": resumes}, kind="done")
    assert describe_resume(tmp_path, reached) == expected


def test_a_failed_connection_is_one_line_naming_a_wrong_token():
    """Ray wraps the GCS's refusal of a token into the text of the errors it raises."""
    try:
        try:
            raise RuntimeError(
                "Failed to connect to GCS. Last connection error: Traceback (most recent call "
                "last):\n  ...\nray.exceptions.AuthenticationError: RPC error: "
                "InvalidAuthToken: Authentication token is missing or incorrect."
            )
        except RuntimeError as inner:
            raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.7:26379") from inner
    except ConnectionError as error:
        assert ray_executor._why_not_connected(error) == (
            "its authentication token is missing or wrong here (set RAY_AUTH_MODE=token and "
            "RAY_AUTH_TOKEN_PATH to the token file the cluster was started with)"
        )
    other = ConnectionError("Failed to connect to Ray cluster at 192.0.2.7:26379\nmore")
    assert ray_executor._why_not_connected(other) == (
        "Failed to connect to Ray cluster at 192.0.2.7:26379"
    )
