"""The safety layer between a plan and the world it runs in, below both the simulated
evaluations (`distgprl.experiments`) and the hardware trials (`distgprl.hardware`):
plan_check.py (the pre-flight check against `distgprl.limits.SafetyLimits`), retime.py
(TOPP-RA retiming), push.py (the least-norm via-point push), repair.py (retime, push or
refuse: `repair_plan`), window_check.py (one window's clearance oracles and via-points) and
gates.py (the protocols as gates of the episode loop, `distgprl.envs.episode`)."""
