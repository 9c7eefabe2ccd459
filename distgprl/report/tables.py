"""Every results table of a preset from its result files only (`write_tables`), each made by
its module, written with a metadata sidecar per CSV; a table the results no longer make is
removed. Table I, its per-run table, the aggregates and the claims report `TABLE_POLICY`'s
evaluations (docs/findings/protocol.md, rule 6)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.methods import STUDY_METHODS
from distgprl.report import paired, table1, table2
from distgprl.report.aggregate import Scores, aggregate_texts, tasks_of
from distgprl.report.claims import claims_texts
from distgprl.report.frame import Frames, load_frames
from distgprl.report.markdown import write_table_files
from distgprl.report.onsets import onset_texts
from distgprl.report.repair import repair_texts
from distgprl.report.robustness import robustness_texts, study_verdicts
from distgprl.report.runs import TABLE_POLICY
from distgprl.studies import studies_of
from distgprl.trial_protocol import TABLE2_POLICY, TRIAL_POLICIES, file_policy

Table = tuple[str, tuple[str, ...] | None, str]
"""One table: file stem, its texts (CSV, Markdown and for Tables I and II LaTeX; None: remove
the files) and the CSV sidecar's description."""

ABOUT = {
    "table1": "Table I ({which}): per task, each metric's mean, sample std and 95 % t-interval "
    "over seeds (ci_low, ci_high; empty for one seed)",
    "per_seed": "Table I per run ({which}): every seed's metrics, late learning-curve means and "
    "training wall time",
    "one_demo": "the one-demonstration ProMP-RRL study beside Table I, Table I's columns",
    "aggregates": "mean, IQM and probability of improvement over seeds with 95 % "
    "stratified-bootstrap intervals (distgprl.report.aggregate)",
    "claims": "each claim of the paper, the statistic testing it and the verdict "
    "(rules: distgprl.report.claims)",
    "robustness": "each claim's verdict under every reading of {names} "
    "(rules: distgprl.report.robustness)",
    "onsets": "the {name} study's learning-curve onsets per reading and seed "
    "(rules: distgprl.report.onsets)",
    "table2": "Table II: hardware trials per method; rates with the exact 95 % binomial interval",
    "noise": "digital twin success and collision against the sensor-noise level",
    "repair": "Table I + repair: the hardware safety layer in the loop in simulation "
    "(distgprl.report.repair)",
}
"""Each table's sidecar description; ``which``, ``names`` and ``name`` are formatted in per
table."""

ONE_DEMO_STUDY = ("promp-rrl", "promp-rrl-1demo", "promp-nominal", "promp-nominal-1demo")
"""The one-demonstration study's rows (protocol rule 3)."""


def write_tables(
    root: str | Path, preset: str, out_dir: str | Path, against: str | None = None
) -> list[Path]:
    """Write every table of ``<root>/<preset>`` to ``out_dir`` and return the paths; with
    ``against``, also each run paired with the same run of that preset."""
    best = load_frames(root, preset, TABLE_POLICY)
    tables = _table_one(best, root, preset, TABLE_POLICY)  # first: no runs, nothing written
    tables += _table_one(load_frames(root, preset, "final"), root, preset, "final")
    scores = table1.collect_scores(best)  # the claims follow Table I
    sizes = (None, *paired.supplementary_sizes(root, preset))
    tables += [
        _one_demo_study(root, preset),
        (f"aggregates_{preset}", aggregate_texts(scores, preset), ABOUT["aggregates"]),
        (f"claims_{preset}", claims_texts(scores, preset), ABOUT["claims"]),
        *_study_tables(root, preset, best, scores),
        *(paired.paired_table(root, preset, ref, n) for ref in paired.REFERENCES for n in sizes),
        paired.paired_table(root, preset, paired.FINAL_POLICY),
        *([paired.paired_table(root, preset, base_preset=against)] if against else []),
        *_table_two(root, preset),
        (f"table1_repair_{preset}", repair_texts(root, preset), ABOUT["repair"]),
    ]
    out_dir = Path(out_dir)
    extra = {"rate_intervals_clipped_to": list(table1.RATE_BOUNDS)}
    written = []
    for stem, texts, description in tables:
        suffixes = (".csv", ".md", ".tex")[: 3 if texts is None else len(texts)]
        written += write_table_files(out_dir / stem, suffixes, texts, preset, description, **extra)
    for stale in out_dir.glob(f"paired_vs_*_{preset}_n*.*"):  # sizes no longer present
        if stale not in written:
            stale.unlink()
    return written


def _table_two(root: str | Path, preset: str) -> list[Table]:
    """Table II of each trial policy's trials (`TRIAL_POLICIES`: Table II's own first, then
    beside it `table2_<policy>` where a trained policy's trials ran it, of the noise-free
    settings its trials run), and Table II's noise table."""
    tables, rows_of = [], {}
    for policy in TRIAL_POLICIES:
        trials = table2.select_trial_files(root, preset, policy)
        ran = policy == TABLE2_POLICY or any(file_policy(m) == policy for _, m, _ in trials.counted)
        rows = rows_of[policy] = table2.hardware_rows(trials) if ran else []
        if policy != TABLE2_POLICY:  # its trials' settings: Table II's noise-free ones
            rows = [row for row in rows if row["sensor_noise"] in ("0", "–")]
        texts = table2.hardware_texts(rows, preset, trials.note(), policy) if rows else None
        tables.append((f"{table2.table2_stem(policy)}_{preset}", texts, ABOUT["table2"]))
    noise = table2.noise_texts(rows_of[TABLE2_POLICY], preset)
    return [*tables, (f"table2_noise_{preset}", noise, ABOUT["noise"])]


def _table_one(frames: Frames, root: str | Path, preset: str, policy: str) -> list[Table]:
    """Table I and its per-run table of the ``policy`` evaluations (``frames``).

    Raises:
        UserInputError: the preset has no evaluated run.
    """
    rows, tasks = table1.simulation_table(frames)
    if not rows:
        raise UserInputError(f"{Path(root) / preset}: no summary.json files; run a sweep first")
    stem = f"table1_{preset}" if policy == TABLE_POLICY else f"table1_{policy}_{preset}"
    which = "best learning-curve policy" if policy == "best" else f"{policy} policy"
    texts = table1.table1_texts(rows, tasks, preset, frames.runs.attrs["note"], policy)
    per_seed = table1.per_seed_texts(table1.per_seed_rows(frames), preset, policy)
    return [
        (stem, texts, ABOUT["table1"].format(which=which)),
        (f"{stem}_per_seed", per_seed, ABOUT["per_seed"].format(which=which)),
    ]


def _one_demo_study(root: str | Path, preset: str) -> Table:
    """Table I's columns (CSV, Markdown) for `ONE_DEMO_STUDY`'s runs; None (no file) without a
    study method's run."""
    frames = load_frames(root, preset, TABLE_POLICY, methods=ONE_DEMO_STUDY)
    rows, tasks = table1.simulation_table(frames, ONE_DEMO_STUDY)
    if not any(row["method"] in STUDY_METHODS for row in rows):
        return (f"one_demo_study_{preset}", None, ABOUT["one_demo"])
    heading = (
        f"The one-demonstration ProMP-RRL study beside Table I ({preset} preset, "
        f"{table1.POLICY_TITLES[TABLE_POLICY]}): ProMP-RRL and ProMP nominal are Table I's, over "
        "20 demonstrations (protocol v8, rule 3); the (1 demo) rows fit the ProMP's nominal to "
        "the one demonstration every GP method gets. Not part of Table I or the claims"
    )
    note = frames.runs.attrs["note"]
    texts = table1.table1_texts(rows, tasks, preset, note, TABLE_POLICY, heading)
    return (f"one_demo_study_{preset}", texts[:2], ABOUT["one_demo"])


def _study_tables(root: str | Path, preset: str, frames: Frames, scores: Scores) -> Iterator[Table]:
    """Beside a preset with studies (`studies_of`): each claim under every reading of every
    study at the studies' seeds (Table I's ``frames`` among them), and each study's onsets."""
    studies = studies_of(preset)
    if not studies:
        return
    if len({study.seeds for study in studies}) > 1:
        raise ValueError(f"the studies beside {preset} compare at different seeds")
    seeds = studies[0].seeds
    results = study_verdicts(
        studies,
        table1.collect_scores(frames.of_seeds(seeds)),
        lambda p: table1.collect_scores(load_frames(root, p, TABLE_POLICY, seeds)),
    )
    names = ", ".join(s.name for s in studies)
    about = ABOUT["robustness"].format(names=names)
    yield (f"claims_robustness_{preset}", robustness_texts(results, preset), about)
    for study in studies:
        texts = onset_texts(root, study, tasks_of(scores), preset)
        yield (f"onsets_{study.name}_{preset}", texts, ABOUT["onsets"].format(name=study.name))
