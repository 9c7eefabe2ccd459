"""Benchmarks of the paper's §V figures (`distgprl bench [--quick]`): medians and spreads
with warm-up and repeats.

Sections of `run_benchmarks` (all measured in one process, so ratios compare like with like):

1. **Adaptation compute** per window and per episode, as in the paper (§V): EDF query at the
   window via-points and the tool points, GP conditioning (the window update
   Delta Gamma = S_W a plus re-evaluating the executed segment of the trajectory), policy
   inference of a SAC actor with the real observation size, and the total, side by side with
   the paper's figures and with naive alternatives measured in the same run (PyBullet
   ``getClosestPoints`` for the same points and shapes; re-solving the GP from scratch).
2. The environment's step against the bare physics inside it, in process CPU time
   (``ratios.env_step_over_bare_physics``).
3. One SAC gradient step with the regularised actor loss (batch 256, paper network) vs plain SAC,
   in wall and in process CPU time (the latter is ``ratios.regularised_over_plain_sac_step``).
4. The paper suite's CPU-hours from a timed training step of every trainable method on every
   task (``suite.cpu_hours``, ``suite.hours_two_idle_cores``).
5. The suite's floor (``suite.floor``): the matrix products of a plain SAC update, timed inside
   real updates by a torch dispatch mode, plus the bare physics of section 2, summed over the
   suite's runs; what any implementation of the same algorithm pays on this machine. Beside
   the products, the same plain updates timed without the clock give the update's framework
   work (``suite.floor.sac_update.non_product_ms``), and ``ratios.suite_over_floor`` is
   section 4's CPU-hours over the floor's (issue 49).

Every timing is wall time of the calling process; the machine's load average is recorded
before and after, because other processes sharing the cores inflate every figure. The
studies around these figures (a simulated episode, the GP micro-benchmark, adaptation compute
against via-points and obstacles, training throughput and its breakdown, worker scaling) are
scripts in the repository's ``benchmarks/`` folder, built on the modules here.

Modules (one per section, plus what they share; each name is imported from its module):

- `timing`: `Timing`, `measure`, `measure_interleaved`, `machine_info`.
- `sizes`: `BenchSizes` and the presets table `SIZE_PRESETS` (`FULL_SIZES`, `QUICK_SIZES`,
  `TINY_SIZES`); `run_spec`, the measured run.
- `pipeline`: `AdaptationPipeline`; `baselines`: `BulletDistance` and the naive pipeline.
- `adaptation` (1), `environment` (2), `sac_update` (3), `suite` (4), `floor` (5).
- `markdown`, `plots`: the Markdown tables (the site's benchmarks page) and the figure;
  `run`: `run_benchmarks`, `load_results`; `cli`: the argparse `main` of ``python -m
  distgprl.experiments.bench``.
"""
