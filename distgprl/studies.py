"""Studies: named groups of presets that one sweep runs and one report reads (issue 50).

A study answers one question over several readings of a constant the paper leaves open. Its
runs live under each member preset's own folder (``results/<preset>/<task>/<method>/seed<k>``,
with that preset's config hash), so every run is an ordinary run of an ordinary preset; the
study only names which presets and methods belong together, the preset whose Table I they are
read beside, and how each reading is labelled.

``distgprl sweep --preset operators`` runs every member preset's methods (`plan_jobs` expands a
study name), ``distgprl status --preset operators`` shows them, and ``distgprl tables --preset
paper`` writes the study's outputs beside Table I (``claims_robustness_paper``, the sensitivity
figure), from the result files alone.

The operator study (docs/findings/protocol.md, rule 3): Table I's Dist-GPRL uses the
zero-mean GP operator of Eq. 1 per axis; the three other defensible readings of K_tt in
S = K (K + lambda I)^-1 ship as presets and are run for Dist-GPRL only. A claim is reproduced
only where it holds under every reading (`distgprl.report.robustness`). Its control
(``operator-signal-uncoupled``, pre-registered in docs/findings/operator.md) is not a reading:
the signal reading's per-via-point reach without its coupling, run and drawn beside the
readings to tell which of the two lets that reading learn DCP early; no verdict reads it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from distgprl.errors import UserInputError
from distgprl.identity import SWEEP_SEEDS
from distgprl.methods import METHODS

__all__ = [
    "STUDIES",
    "OnsetRule",
    "Reading",
    "Study",
    "get_study",
    "is_study",
    "studies_of",
    "study_of_reading",
]


@dataclass(frozen=True)
class OnsetRule:
    """A pre-registered decision rule on one reading's learning-curve onsets, fixed before
    its first run: on ``task`` a run *learns early* if its learning curve's success reaches
    ``threshold`` at a curve point after step 0 (the untrained policy) and at or before step
    ``by_step``; of the runs at ``seeds``, ``at_least`` or more learning early give
    ``if_early``, ``at_most`` or fewer ``if_late``, any count between ``if_between``
    (`distgprl.report.onsets`).

    Attributes:
        name: the rule's name, unique within its study (tables and ``given`` use it).
        task: the task the rule reads.
        threshold: success on the curve TCs that counts as learned.
        by_step: the last training step at which reaching ``threshold`` counts as early.
        seeds: the seeds of the runs the rule reads; fewer of them finished: awaiting.
        at_least: the least count of early runs for ``if_early``.
        at_most: the largest count of early runs for ``if_late``.
        if_early: the conclusion when ``at_least`` or more runs learn early.
        if_late: the conclusion when ``at_most`` or fewer do.
        if_between: the conclusion for a count between (empty: undecided).
        given: the name of another rule of the study whose ``if_early`` this rule needs:
            while that rule awaits its runs this one does too, and any other verdict of it
            makes this one void (empty: none).
    """

    name: str
    task: str
    threshold: float
    by_step: int
    seeds: tuple[int, ...]
    at_least: int
    at_most: int
    if_early: str
    if_late: str
    if_between: str = ""
    given: str = ""

    def __post_init__(self) -> None:
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"rule {self.name!r}: a seed repeats: {self.seeds}")
        if not 0 <= self.at_most < self.at_least <= len(self.seeds):
            raise ValueError(
                f"rule {self.name!r}: need 0 <= at_most < at_least <= {len(self.seeds)} seeds"
            )


@dataclass(frozen=True)
class Reading:
    """One reading of the studied constant: the preset that implements it and its label.

    Attributes:
        preset: the preset whose runs are this reading's (``paper`` for Table I's).
        label: short name used in tables and figures.
        changes: the (``section.field``, value) pairs in which the preset's configuration
            differs from the reference preset's — documentation and a consistency test (the
            preset file is the one source of the values; empty for the reference).
        control: a control, not a reading of the paper: run, tabled and drawn with the
            study, but no claim's verdict reads it (`Study.claim_readings`).
        rules: the pre-registered decision rules on this reading's onsets (`OnsetRule`).
    """

    preset: str
    label: str
    changes: tuple[tuple[str, object], ...] = ()
    control: bool = False
    rules: tuple[OnsetRule, ...] = ()


TABLE_ONE = " (Table I)"
"""How a reference reading's label names Table I's value of the studied constant."""


def table_one_reading(value: str, preset: str = "paper") -> Reading:
    """The reference reading of a study: ``preset``'s runs, labelled by Table I's ``value`` of
    the studied constant, e.g. "zero-mean GP (Table I)"."""
    return Reading(preset, f"{value}{TABLE_ONE}")


@dataclass(frozen=True)
class Study:
    """A named group of presets run by one sweep and reported beside a reference preset.

    Attributes:
        name: the name ``--preset`` accepts for the study (not a preset itself).
        reference: the reading of the reference preset (Table I's); its runs are that preset's.
        readings: the study's own readings, each a preset run for ``methods``.
        methods: the methods the study trains under each of ``readings``.
        question: one sentence: what the study answers.
        acts_on: the `MethodSpec` flag that marks the methods whose runs a reading changes
            (``covariance_transform``: the operator acts on the methods that apply S_W;
            ``trainable``: a reward constant changes every trained method).
        seeds: the seeds at which the readings are compared (Table I's): every table,
            figure and verdict of the study reads these; runs at other seeds are read by
            the rules that name them only (`OnsetRule.seeds`).
    """

    name: str
    reference: Reading
    readings: tuple[Reading, ...]
    methods: tuple[str, ...]
    question: str
    acts_on: str = "covariance_transform"
    seeds: tuple[int, ...] = SWEEP_SEEDS

    def __post_init__(self) -> None:
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"study {self.name!r}: seeds must be distinct and some: {self.seeds}")
        if self.reference.rules:
            raise ValueError(
                f"study {self.name!r}: a rule belongs to a study reading, not its reference"
            )
        rules = self.rules
        names = [rule.name for _, rule in rules]
        if len(set(names)) != len(names):
            raise ValueError(f"study {self.name!r}: rule names repeat: {names}")
        needs = {rule.name: rule.given for _, rule in rules}
        for name in names:  # follow each rule's chain of needed rules to its end
            chain = [name]
            while given := needs[chain[-1]]:
                if given not in needs:
                    raise ValueError(f"rule {chain[-1]!r} needs unknown rule {given!r}")
                if given in chain:
                    raise ValueError(f"rules need each other in a circle: {chain}")
                chain.append(given)
        if len({(rule.threshold, rule.by_step) for _, rule in rules}) > 1:
            raise ValueError(f"study {self.name!r}: its rules differ in threshold or by_step")

    @property
    def rules(self) -> tuple[tuple[Reading, OnsetRule], ...]:
        """Every reading's rules, with their reading, in the readings' order."""
        return tuple((reading, rule) for reading in self.readings for rule in reading.rules)

    def planned_runs(
        self,
        methods: Sequence[str] | None,
        tasks: Sequence[str],
        seeds: Sequence[int] | None = None,
    ) -> list[tuple[str, str, str, int]]:
        """(preset, method, task, seed) of the runs the study's sweep trains, in order: seed by
        seed, every reading's preset for ``methods`` (default: the study's) on ``tasks``; then,
        without ``seeds`` (default: `seeds`), each rule's runs at its seeds (its reading, the
        study's first method, its task — where ``methods`` and ``tasks`` include them)."""
        runs = [
            (preset, method, task, seed)
            for seed in (self.seeds if seeds is None else seeds)
            for preset in self.presets
            for method in (methods or self.methods)
            for task in tasks
        ]
        method = self.methods[0]
        if seeds is None and (not methods or method in methods):
            runs += [
                (reading.preset, method, rule.task, seed)
                for reading, rule in self.rules
                if rule.task in tasks
                for seed in rule.seeds
            ]
        return list(dict.fromkeys(runs))

    def rule(self, name: str) -> tuple[Reading, OnsetRule]:
        """(reading, rule) of the rule ``name``; a `KeyError` names the study's rules."""
        for reading, rule in self.rules:
            if rule.name == name:
                return reading, rule
        raise KeyError(
            f"study {self.name!r} has no rule {name!r}: {[r.name for _, r in self.rules]}"
        )

    @property
    def reads_the_operator(self) -> bool:
        """Whether the readings are covariance operators (their reach is measured and the
        sensitivity figure drawn against it)."""
        return self.acts_on == "covariance_transform"

    def acted_on(self, method: str) -> bool:
        """Whether a reading of this study changes ``method``'s runs."""
        return bool(getattr(METHODS[method], self.acts_on))

    @property
    def presets(self) -> tuple[str, ...]:
        """The presets the study's sweep runs (its readings', not the reference's)."""
        return tuple(reading.preset for reading in self.readings)

    @property
    def claim_readings(self) -> tuple[Reading, ...]:
        """The study's readings of the paper (its controls left out): the ones the claims'
        verdicts per reading judge (`distgprl.report.robustness`)."""
        return tuple(reading for reading in self.readings if not reading.control)

    @property
    def all_readings(self) -> tuple[Reading, ...]:
        """The reference reading first, then the study's."""
        return (self.reference, *self.readings)


REACH = (
    "reach: the signal reading's early escape is its smaller per-via-point step; its "
    "coupling is not needed for it"
)
"""The operator study control's conclusion when enough of its runs learn early."""

COUPLING = "coupling: the signal reading's reach without its coupling does not escape early"
"""The operator study control's conclusion when too few of its runs learn early."""

STUDIES: dict[str, Study] = {
    "operators": Study(
        name="operators",
        reference=table_one_reading("zero-mean GP"),
        readings=(
            Reading("operator-unit", "unit variance (v4)", (("env.covariance_scale", "unit"),)),
            Reading(
                "operator-signal",
                "per-axis signal (v5)",
                (("env.covariance_scale", "signal"),),
                # docs/findings/operator.md, "The uncoupled-signal control, stage 2"
                rules=(
                    OnsetRule(
                        name="stage 2 replication",
                        task="dcp",
                        threshold=0.5,
                        by_step=4500,
                        seeds=(5, 6, 7, 8, 9),
                        at_least=4,
                        at_most=3,
                        if_early="replicated: the signal reading learns early at new seeds",
                        if_late="not replicated: the signal reading's early escape does not "
                        "hold at new seeds",
                    ),
                ),
            ),
            Reading(
                "operator-correlation",
                "correlation only",
                (("env.covariance_scale", "correlation"),),
            ),
            Reading(
                "operator-signal-uncoupled",
                "signal reach, uncoupled (control)",
                (("env.covariance_scale", "signal-uncoupled"),),
                control=True,
                rules=(
                    # docs/findings/operator.md, "The uncoupled-signal control"
                    OnsetRule(
                        name="stage 1",
                        task="dcp",
                        threshold=0.5,
                        by_step=4500,
                        seeds=(0, 1, 2, 3, 4),
                        at_least=4,
                        at_most=1,
                        if_early=REACH,
                        if_late=COUPLING,
                    ),
                    # docs/findings/operator.md, "… stage 2": independent seeds
                    OnsetRule(
                        name="stage 2",
                        task="dcp",
                        threshold=0.5,
                        by_step=4500,
                        seeds=tuple(range(5, 15)),
                        at_least=8,
                        at_most=2,
                        if_early=REACH,
                        if_late=COUPLING,
                        if_between=(
                            "both: the signal reading's reach without its coupling escapes "
                            "early on some seeds, less reliably than with it; each contributes"
                        ),
                        given="stage 2 replication",
                    ),
                ),
            ),
        ),
        methods=("dist-gprl",),
        question=(
            "Is a claim the paper's, or one reading of K_tt in the covariance operator "
            "S = K (K + lambda I)^-1 the paper leaves open?"
        ),
    ),
}
"""Every study, by name."""

for _study in STUDIES.values():  # a study's methods are registered methods (checked at import)
    for _method in _study.methods:
        if _method not in METHODS:
            raise ValueError(f"study {_study.name!r}: unknown method {_method!r}")


def is_study(name: str) -> bool:
    """Whether ``name`` names a study rather than a preset."""
    return name in STUDIES


def get_study(name: str) -> Study:
    """The study ``name``; a `UserInputError` lists the valid names."""
    try:
        return STUDIES[name]
    except KeyError:
        raise UserInputError(
            f"unknown study {name!r}; valid studies: {', '.join(STUDIES)}"
        ) from None


def study_of_reading(preset: str) -> Study | None:
    """The study one of whose readings (or controls) ``preset`` is, or None."""
    return next((s for s in STUDIES.values() if preset in s.presets), None)


def studies_of(reference_preset: str) -> tuple[Study, ...]:
    """The studies read beside ``reference_preset``'s Table I."""
    return tuple(s for s in STUDIES.values() if s.reference.preset == reference_preset)
