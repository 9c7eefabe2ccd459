"""`make test-cluster`: the sweep on a two-node Ray cluster (issue 52), with its faults.

A head and a worker node are started as separate Ray nodes on this machine (``ray start``
on 127.0.0.1, one CPU each, ports and temporary folders of their own: `ray_nodes`), with
one results root they share. Then:

1. **Worker lost.** ``distgprl sweep --executor ray`` of the seed-0 runs; once the worker
   node's run has written its first checkpoint, the worker's raylet is killed (SIGKILL).
   The sweep must finish (exit 0): Ray retries the lost task on the head, which resumes the
   run from its checkpoint once the lost process has ended — or, on a loaded machine, that
   process finishes the run before it notices its raylet is gone, and the run counts as
   finished by the lost node (as in phase 2). Re-running the same command then has nothing
   left to do.
2. **Worker frozen.** A new worker node joins; the sweep of the seed-2 runs starts, and
   once the worker trains a run past its first checkpoint every process of that node is
   stopped (SIGSTOP: a node cut off or hung) until the head declares it dead, then let go on
   (SIGCONT: the partition heals). Its process must end, the retry must take the run's lock
   only after that, and the sweep must finish (exit 0) with the run resumed — or, on a loaded
   machine, the thawed process finishes the run (it holds the lock) before Ray ends it:
   then the retry skips it, or the frozen node's own task delivers the result first, and
   the run counts as finished by the lost node, not resumed. (Ray's health check is
   shortened for the test, `HEALTH_CHECK`.)
3. **Head lost.** Another worker node joins; the sweep of the seed-1 runs starts, and once
   the head trains a run past its first checkpoint every process of the head is killed
   (SIGKILL). The sweep must exit 4 with one line saying to restart the cluster and re-run.
   A new cluster is started (the old worker node's processes are left to die as Ray makes
   them) and the same command re-run: it must finish (exit 0), resuming the lost runs.
4. **Local.** The same runs with the local executor, in another results root.
5. **Counts and comparison.** Every run of the cluster root is audited (`audit_run`:
   verdict, duplicated steps or episodes, checkpoint manifests, leftovers) and compared
   with the local one in every value but timings (`compare_runs`).

It prints the counts (runs complete / lost / resumed / duplicated / corrupt) and the
comparison, and exits 1 if anything is duplicated, corrupt, incomplete or differs, or a
fault was not met as described. Only the processes it started are ever killed (by PID).

Usage: ``python scripts/cluster_test.py [--methods gprl-d,gprl-h,gprl] [--task dcp]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ray_nodes import LocalCluster, alive  # noqa: E402

from distgprl.experiments.audit import audit_run, compare_runs  # noqa: E402
from distgprl.experiments.ray_executor import CLUSTER_LOST_EXIT  # noqa: E402
from distgprl.schema import read_csv, read_json, run_dir  # noqa: E402

DISTGPRL = str(Path(sys.executable).with_name("distgprl"))
PRESET = "ci"
SWEEP_TIMEOUT_S = 900
FREEZE_AT_MOST_S = 60.0
"""How long a frozen worker node stays frozen if the head has not declared it dead by then
(with `HEALTH_CHECK`, the head declares it dead within about 10 s)."""
GONE_WITHIN_S = 30.0
"""After the sweep of phase 1 or 2 ends, how long the lost node's processes may linger."""

HEALTH_CHECK = {
    "RAY_health_check_initial_delay_ms": "1000",
    "RAY_health_check_period_ms": "1000",
    "RAY_health_check_timeout_ms": "2000",
    "RAY_health_check_failure_threshold": "5",
}
"""Ray's node health check, shortened for the test (Ray's defaults: 3 s period, 10 s
timeout, 5 failures: a node that stops answering is declared dead after about a minute,
measured 63 s): the frozen worker node of phase 2 is declared dead in seconds."""


def log(message: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def held_runs(pids: list[int]) -> dict[int, Path]:
    """The run folder whose lock each of ``pids`` holds (an exclusive ``flock`` on its
    ``.lock``, as /proc/locks lists it): the run that process trains. A process that only
    has the file open (probing it, or waiting for it) is not counted."""
    opened = {}  # inode of an open .lock -> its run folder
    for pid in pids:
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.endswith("/.lock"):
                    opened[(pid, os.stat(f"/proc/{pid}/fd/{fd}").st_ino)] = Path(target).parent
        except OSError:  # ended meanwhile
            continue
    out = {}
    for line in Path("/proc/locks").read_text().splitlines():
        words = line.split()  # "1: FLOCK ADVISORY WRITE <pid> <major>:<minor>:<inode> 0 EOF"
        if len(words) >= 6 and words[1] == "FLOCK" and words[3] == "WRITE":
            pid, inode = int(words[4]), int(words[5].rsplit(":", 1)[1])
            if (pid, inode) in opened:
                out[pid] = opened[(pid, inode)]
    return out


def past_first_checkpoint(folder: Path) -> bool:
    """A run that has a checkpoint to resume from and is not finished."""
    return (folder / "checkpoints" / "manifest.json").exists() and not (
        folder / "done.json"
    ).exists()


@dataclass
class Sweep:
    """One ``distgprl sweep`` process and its output."""

    name: str
    command: list[str]
    env: dict[str, str]
    logs: Path
    process: subprocess.Popen | None = None
    started: float = 0.0

    def start(self) -> Sweep:
        self.out = open(self.logs / f"{self.name}.out", "w")  # noqa: SIM115
        self.err = open(self.logs / f"{self.name}.err", "w")  # noqa: SIM115
        self.started = time.monotonic()
        env = {**self.env, "PYTHONUNBUFFERED": "1"}  # its lines as they come
        self.process = subprocess.Popen(self.command, env=env, stdout=self.out, stderr=self.err)
        return self

    def wait(self, until: Callable[[], bool] | None = None, poll_s: float = 0.1) -> int:
        """Wait for the sweep to end; ``until`` is called meanwhile (True: stop calling)."""
        assert self.process is not None
        deadline = time.monotonic() + SWEEP_TIMEOUT_S
        while self.process.poll() is None:
            if time.monotonic() > deadline:
                self.process.kill()
                raise RuntimeError(f"sweep {self.name} did not end within {SWEEP_TIMEOUT_S} s")
            if until is not None and until():
                until = None
            time.sleep(poll_s)
        self.out.close()
        self.err.close()
        return self.process.returncode

    def stdout(self) -> str:
        return (self.logs / f"{self.name}.out").read_text()

    def stderr(self) -> str:
        return (self.logs / f"{self.name}.err").read_text()


@dataclass
class Record:
    """What the faults did, for the report."""

    lost: dict[str, str] = field(default_factory=dict)  # run folder -> which fault
    # lost runs the lost node's own process finished after it went on (no resume needed)
    finished_by_lost: set[str] = field(default_factory=set)
    checks: list[tuple[str, bool, str]] = field(default_factory=list)  # (what, ok, detail)
    seconds: dict[str, float] = field(default_factory=dict)

    def check(self, what: str, ok: bool, detail: str = "") -> None:
        self.checks.append((what, ok, detail))
        log(f"{'ok  ' if ok else 'FAIL'} {what}{': ' + detail if detail else ''}")


def sweep_command(root: Path, methods: str, task: str, seeds: str, address: str | None):
    command = [DISTGPRL, "sweep", "--preset", PRESET, "--methods", methods, "--tasks", task]
    command += ["--seeds", seeds, "--root", str(root), "--heartbeat", "0"]
    command += ["--workers", "2"]
    if address:
        command += ["--executor", "ray", "--address", address]
    return command


def worker_lost(cluster: LocalCluster, root: Path, args, logs: Path, record: Record) -> None:
    """Phase 1: kill the worker node's raylet while it trains a run. Its process must end
    before Ray's retry on the head takes the run's lock — or, on a loaded machine, it
    finishes the ``ci`` run (seconds from its end) before it notices its raylet is gone;
    then the retry finds the run finished. Both keep one writer; `check_lost_run` says
    which happened."""
    env = {**cluster.env(), "DISTGPRL_CHECKPOINT_ROOT": ""}
    command = sweep_command(root, args.methods, args.task, "0", cluster.address)
    worker = cluster.node("worker")
    state: dict = {}

    def kill_worker_mid_run() -> bool:
        for pid, folder in held_runs(worker.job_processes()).items():
            if past_first_checkpoint(folder):
                jobs = worker.job_processes()
                raylet = worker.raylet()
                cluster.kill("worker", raylet_only=True)
                state.update(folder=folder, pid=pid, jobs=jobs, at=time.monotonic())
                log(f"killed the worker's raylet {raylet}; its process {pid} trained {folder}")
                record.lost[str(folder)] = "worker node lost"
                return True
        return False

    def watch_retry() -> bool:
        if "at" not in state:
            kill_worker_mid_run()
            return False
        watch_lost_run(state, cluster.node("head").job_processes())
        return "gone" in state and ("retry" in state or "finished" in state)

    sweep = Sweep("1-worker-lost", command, env, logs).start()
    code = sweep.wait(until=watch_retry)
    wait_gone(state)
    record.seconds["sweep with the worker lost"] = time.monotonic() - sweep.started
    record.check("a worker node was killed mid-run", "at" in state)
    if "at" not in state:
        return
    check_lost_run(record, state, code, sweep.stdout())
    again = Sweep("1-worker-lost-rerun", command, env, logs).start()
    code = again.wait()
    record.check(
        "re-running the same command has nothing left to do",
        code == 0 and "already done: " in again.stdout() and ": done" not in again.stdout(),
        f"exit {code}",
    )


def worker_frozen(cluster: LocalCluster, root: Path, args, logs: Path, record: Record) -> None:
    """Phase 2: freeze a worker node (SIGSTOP to every process of it, as a node cut off
    from the network or hung) while it trains a run, until the head declares it dead; then
    let it go on (SIGCONT), as a partition that heals. Its process must not train beside
    the retry: Ray retries the task once the frozen process is gone, and the retry takes
    the run's lock only after it. On a loaded machine the thawed process may instead finish
    the run (it holds the lock) in the moment before Ray ends it, a ``ci`` run being
    seconds from its end; then the retry finds the run finished and skips it. Both keep one
    writer per run; which one happened is reported."""
    worker = cluster.start_worker("worker2", slot=2)
    env = {**cluster.env(), "DISTGPRL_CHECKPOINT_ROOT": ""}
    command = sweep_command(root, args.methods, args.task, "2", cluster.address)
    state: dict = {}
    sweep = Sweep("2-worker-frozen", command, env, logs)

    def freeze_then_thaw() -> bool:
        if "at" not in state:
            for pid, folder in held_runs(worker.job_processes()).items():
                if past_first_checkpoint(folder):
                    jobs = worker.job_processes()
                    frozen = cluster.signal("worker2", signal.SIGSTOP)
                    state.update(folder=folder, jobs=jobs, frozen=frozen, at=time.monotonic())
                    log(f"froze the worker node ({len(frozen)} processes); {pid} trained {folder}")
                    record.lost[str(folder)] = "worker node frozen"
            return False
        since = time.monotonic() - state["at"]
        if "thawed" not in state:
            if "marked dead" in sweep.stdout() or since > FREEZE_AT_MOST_S:
                state["dead"] = "marked dead" in sweep.stdout()
                cluster.signal("worker2", signal.SIGCONT, state["frozen"])
                state["thawed"] = since
                log(f"the head declared it dead: {state['dead']}; let it go on after {since:.1f} s")
            return False
        watch_lost_run(state, cluster.node("head").job_processes())
        return "retry" in state and "gone" in state

    sweep.start()
    code = sweep.wait(until=freeze_then_thaw, poll_s=0.1)
    if state.get("frozen") and "thawed" not in state:  # never leave it stopped
        cluster.signal("worker2", signal.SIGCONT, state["frozen"])
    wait_gone(state)
    record.seconds["sweep with a worker frozen"] = time.monotonic() - sweep.started
    record.check("a worker node was frozen mid-run", "at" in state)
    if "at" not in state:
        return
    record.check(
        "the head declared the frozen node dead",
        bool(state.get("dead")),
        f"let go on {state.get('thawed', float('nan')):.1f} s after the freeze",
    )
    check_lost_run(record, state, code, sweep.stdout())


def watch_lost_run(state: dict, head_jobs: list[int]) -> None:
    """One poll after a node was lost mid-run (``state``: ``folder`` the run it trained,
    ``jobs`` its job processes, ``at`` when). Notes, in seconds after ``at``: ``retry``
    when a process of the head (``head_jobs``) took the run's lock, with ``collision``
    whether a lost process still held it then; ``finished`` when done.json appeared while
    no retry held the lock (only the lost process can have written it); ``gone`` when
    every lost process had ended."""
    since = time.monotonic() - state["at"]
    if "retry" not in state and state["folder"] in held_runs(head_jobs).values():
        state["retry"] = since
        state["collision"] = state["folder"] in held_runs(state["jobs"]).values()
    if "retry" not in state and "finished" not in state:
        if (state["folder"] / "done.json").exists():
            state["finished"] = since
    if "gone" not in state and not any(alive(pid) for pid in state["jobs"]):
        state["gone"] = since


def wait_gone(state: dict) -> None:
    """After the sweep ends: the lost run may have been finished by the lost process
    before the last poll saw done.json, or that process may not be gone yet; keep
    watching (no retry can start any more) for up to `GONE_WITHIN_S`."""
    deadline = time.monotonic() + GONE_WITHIN_S
    while "at" in state and "gone" not in state and time.monotonic() < deadline:
        watch_lost_run(state, [])
        time.sleep(0.1)


def check_lost_run(record: Record, state: dict, code: int, out: str) -> None:
    """The checks every lost worker run must pass (phases 1 and 2), from what
    `watch_lost_run` saw and the sweep's exit ``code`` and output ``out``."""
    finished_by_lost, ok, detail = lost_outcome(state)
    record.check(
        "its process ended, and Ray's retry took the run's lock only after that "
        "(or it finished the run first and no retry trained it)",
        ok,
        detail,
    )
    name = "/".join(state["folder"].parts[-3:])
    record.check("the sweep finished (exit 0)", code == 0, f"exit {code}")
    if finished_by_lost:
        record.finished_by_lost.add(str(state["folder"]))
    record.check(
        "the sweep reported the lost run "
        + ("skipped or done" if finished_by_lost else "resumed from its checkpoint"),
        lost_run_reported(out, name, finished_by_lost),
        next((line for line in out.splitlines() if name in line and ": " in line), ""),
    )


def lost_outcome(state: dict) -> tuple[bool, bool, str]:
    """A lost run's outcome from what `watch_lost_run` saw. Returns (the lost process
    finished the run itself, one writer was kept, detail): either its process was gone
    before the retry took the lock, or it finished the run and is gone (a retry then found
    it done)."""
    nan = float("nan")
    finished_by_lost = "finished" in state
    retried_after = "retry" in state and state.get("gone", 1e9) <= state["retry"]
    ok = not state.get("collision") and (retried_after or (finished_by_lost and "gone" in state))
    if finished_by_lost:
        detail = (
            f"it finished the run {state['finished']:.1f} s after the fault (process gone "
            f"{state.get('gone', nan):.1f} s); no retry trained it"
        )
    else:
        detail = (
            f"process gone {state.get('gone', nan):.1f} s, retry took the lock "
            f"{state.get('retry', nan):.1f} s after the fault"
        )
    return finished_by_lost, ok, detail


def lost_run_reported(out: str, name: str, finished_by_lost: bool) -> bool:
    """Whether the sweep's output ``out`` reports run ``name`` (``dcp/gprl-d/seed2``) as
    the fault left it: ``<run>: skipped in 0 s`` (Ray's retry found it finished) or
    ``<run>: done in 1 s`` (the lost node's own task delivered it) when the lost process
    finished it, else ``<run>: done in 3 s (resumed from its checkpoint of step 120)``."""
    for line in out.splitlines():
        if finished_by_lost:
            if f"{name}: skipped" in line or f"{name}: done" in line:
                return True
        elif f"{name}: done" in line and "resumed from its checkpoint" in line:
            return True
    return False


def head_lost(cluster: LocalCluster, root: Path, args, logs: Path, record: Record):
    """Phase 3: kill the head while it trains a run; re-run on a new cluster. Returns the
    new cluster."""
    cluster.start_worker("worker3", slot=3)
    env = {**cluster.env(), "DISTGPRL_CHECKPOINT_ROOT": ""}
    command = sweep_command(root, args.methods, args.task, "1", cluster.address)
    state: dict = {}

    def kill_head_mid_run() -> bool:
        head = cluster.node("head")
        for pid, folder in held_runs(head.job_processes()).items():
            if past_first_checkpoint(folder):
                worker_runs = held_runs(cluster.node("worker3").job_processes())
                killed = cluster.kill("head")
                state.update(at=time.monotonic(), worker_runs=worker_runs)
                log(f"killed the head ({len(killed)} processes); its {pid} trained {folder}")
                record.lost[str(folder)] = "head lost"
                return True
        return False

    sweep = Sweep("3-head-lost", command, env, logs).start()
    code = sweep.wait(until=kill_head_mid_run)
    record.check("the head was killed mid-run", "at" in state)
    if "at" not in state:
        return cluster
    after = time.monotonic() - state["at"]
    record.seconds["sweep exit after the head was killed"] = after
    lines = [line for line in sweep.stderr().splitlines() if line.strip()]
    ours = [line for line in lines if line.startswith("sweep: the ray cluster at")]
    record.check(
        f"the sweep exited {CLUSTER_LOST_EXIT}",
        code == CLUSTER_LOST_EXIT,
        f"exit {code} {after:.1f} s after the kill",
    )
    record.check(
        "with one line saying what to do, its last",
        len(ours) == 1
        and lines[-1] == ours[0]
        and "restart the cluster and re-run the same command" in ours[0]
        and not any("Traceback" in line for line in lines),
        ours[0] if ours else (lines[-1] if lines else "(nothing on stderr)"),
    )
    # A new cluster, as after a restart; the old worker node is left as Ray leaves it (its
    # raylet gives up on the head after 60 s; a process of it may still hold a run's lock).
    fresh = LocalCluster(cluster.workdir / "restarted", extra_env=HEALTH_CHECK)
    fresh.start_head()
    fresh.start_worker()
    env = {**fresh.env(), "DISTGPRL_CHECKPOINT_ROOT": ""}
    command = sweep_command(root, args.methods, args.task, "1", fresh.address)
    rerun = Sweep("3-head-lost-rerun", command, env, logs).start()
    code = rerun.wait()
    record.seconds["re-run on the restarted cluster"] = time.monotonic() - rerun.started
    record.check(
        "re-running the same command on a restarted cluster finishes", code == 0, f"exit {code}"
    )
    cluster.stop()  # what is left of the old cluster
    return fresh


def count(root: Path, local: Path, args, record: Record) -> bool:
    """Audit and compare every run; print the counts; True if all is well."""
    runs = [
        run_dir(root, PRESET, args.task, method, seed)
        for seed in (0, 1, 2)
        for method in args.methods.split(",")
    ]
    complete, resumed, restarted, duplicated, corrupt, differ = [], [], [], [], [], []
    details: list[str] = []
    for folder in runs:
        name = "/".join(folder.parts[-3:])
        problems = audit_run(folder)
        duplicates = [p for p in problems if "twice" in p or "strictly increasing" in p]
        others = [p for p in problems if p not in duplicates]
        if duplicates:
            duplicated.append(name)
        if [p for p in others if not p.startswith("verdict")]:
            corrupt.append(name)
        details += [f"  {name}: {p}" for p in problems]
        if not problems:
            complete.append(name)
        if (folder / "done.json").exists():
            resumes = read_json(folder / "done.json").get("resumes") or []
            if any(r.get("step", 0) > 0 for r in resumes):
                resumed.append(name)
            if any(r.get("step", 0) == 0 for r in resumes) or not all(
                r.get("exact") for r in resumes if r.get("step", 0) > 0
            ):
                restarted.append(name)
        if folder.exists():
            steps = [int(r["step"]) for r in read_csv(folder / "progress.csv")[1]]
            if steps != [0, 120, 240]:
                details.append(f"  {name}: learning-curve steps {steps}")
                if len(steps) != len(set(steps)) and name not in duplicated:
                    duplicated.append(name)
        other = run_dir(local, PRESET, args.task, folder.parts[-2], int(folder.name[4:]))
        differences = compare_runs(folder, other) if folder.exists() else ["missing"]
        if differences:
            differ.append(name)
            details += [f"  {name} vs local: {d}" for d in differences[:5]]
    lost = {"/".join(Path(f).parts[-3:]): fault for f, fault in record.lost.items()}
    finished_by_lost = {"/".join(Path(f).parts[-3:]) for f in record.finished_by_lost}
    lost_resumed = [name for name in lost if name in resumed]
    lost_accounted = [name for name in lost if name in resumed or name in finished_by_lost]
    same = len(runs) - len(differ)
    rows = [
        ("complete", len(complete), f"of {len(runs)}"),
        ("lost", len(lost), ", ".join(f"{n} ({fault})" for n, fault in sorted(lost.items()))),
        ("resumed", len(resumed), f"{', '.join(resumed)}; lost ones: {len(lost_resumed)}"),
        (
            "self-done",
            len(finished_by_lost),
            "lost runs the lost node finished itself: "
            + (", ".join(sorted(finished_by_lost)) or "none"),
        ),
        ("restarted", len(restarted), ", ".join(restarted)),
        ("duplicated", len(duplicated), ", ".join(duplicated)),
        ("corrupt", len(corrupt), ", ".join(corrupt)),
        ("identical", same, f"of {len(runs)} vs the local sweep (every value but timings)"),
    ]
    print()
    print(
        f"cluster test: {len(runs)} runs: {PRESET} preset, {args.task}, {args.methods}, seeds 0,1,2"
    )
    for what, number, detail in rows:
        print(f"  {what:<11}{number:3d}  {detail}")
    for line in details:
        print(line)
    checks_ok = all(ok for _, ok, _ in record.checks)
    print(f"  fault checks {sum(ok for _, ok, _ in record.checks)}/{len(record.checks)} passed")
    for what, seconds in record.seconds.items():
        print(f"  {what}: {seconds:.0f} s")
    return (
        checks_ok
        and len(complete) == len(runs)
        and not duplicated
        and not corrupt
        and not differ
        and not restarted
        and len(lost_accounted) == len(lost) > 0
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--methods", default="gprl-d,gprl-h,gprl")
    parser.add_argument("--task", default="dcp")
    parser.add_argument("--workdir", type=Path, help="default: a new folder under /tmp")
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    args = parser.parse_args()
    # short: Ray's socket paths under it must stay under 107 characters
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="dgc-", dir="/tmp"))
    logs = workdir / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    root, local = workdir / "shared" / "results", workdir / "local" / "results"
    record = Record()
    started = time.monotonic()
    clusters = [LocalCluster(workdir / "cluster", extra_env=HEALTH_CHECK)]
    try:
        log(f"work folder {workdir}; starting a head and a worker node")
        clusters[0].start_head()
        clusters[0].start_worker()
        nodes = clusters[0].alive_nodes()
        record.check("two Ray nodes are alive", nodes == 2, f"{nodes} nodes")
        log("phase 1: the worker node is lost mid-run")
        worker_lost(clusters[0], root, args, logs, record)
        log("phase 2: a worker node freezes mid-run, is declared dead, then goes on")
        worker_frozen(clusters[0], root, args, logs, record)
        log("phase 3: the head is lost mid-run")
        clusters.append(head_lost(clusters[0], root, args, logs, record))
    finally:
        for cluster in clusters:
            cluster.stop()
    log("phase 4: the same runs with the local executor")
    t0 = time.monotonic()
    done = subprocess.run(
        sweep_command(local, args.methods, args.task, "0,1,2", None),
        env={**os.environ, "DISTGPRL_CHECKPOINT_ROOT": ""},
        stdout=open(logs / "4-local.out", "w"),  # noqa: SIM115
        stderr=subprocess.STDOUT,
        timeout=SWEEP_TIMEOUT_S,
    )
    record.seconds["local sweep"] = time.monotonic() - t0
    record.check("the local sweep finished", done.returncode == 0, f"exit {done.returncode}")
    ok = count(root, local, args, record)
    print(f"  wall time {time.monotonic() - started:.0f} s; logs in {logs}")
    print(f"cluster test: {'PASSED' if ok else 'FAILED'}")
    if ok and not args.keep and args.workdir is None:
        shutil.rmtree(workdir, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
