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

The operator study (Protocol v6 rule 3, docs/FINDINGS.md): Table I's Dist-GPRL uses the
zero-mean GP operator of Eq. 1 per axis; the three other defensible readings of K_tt in
S = K (K + lambda I)^-1 ship as presets and are run for Dist-GPRL only. A claim is reproduced
only where it holds under every reading (`distgprl.report.robustness`).
"""

from __future__ import annotations

from dataclasses import dataclass

from distgprl.errors import UserInputError
from distgprl.methods import METHODS

__all__ = ["STUDIES", "Reading", "Study", "get_study", "is_study", "studies_of"]


@dataclass(frozen=True)
class Reading:
    """One reading of the studied constant: the preset that implements it and its label.

    Attributes:
        preset: the preset whose runs are this reading's (``paper`` for Table I's).
        label: short name used in tables and figures.
        covariance_scale: the `EnvConfig.covariance_scale` the preset sets (documentation and
            a consistency test; the preset file is the one source of the value).
    """

    preset: str
    label: str
    covariance_scale: str


@dataclass(frozen=True)
class Study:
    """A named group of presets run by one sweep and reported beside a reference preset.

    Attributes:
        name: the name ``--preset`` accepts for the study (not a preset itself).
        reference: the reading of the reference preset (Table I's); its runs are that preset's.
        readings: the study's own readings, each a preset run for ``methods``.
        methods: the methods the study trains under each of ``readings``.
        question: one sentence: what the study answers.
    """

    name: str
    reference: Reading
    readings: tuple[Reading, ...]
    methods: tuple[str, ...]
    question: str

    @property
    def presets(self) -> tuple[str, ...]:
        """The presets the study's sweep runs (its readings', not the reference's)."""
        return tuple(reading.preset for reading in self.readings)

    @property
    def all_readings(self) -> tuple[Reading, ...]:
        """The reference reading first, then the study's."""
        return (self.reference, *self.readings)


STUDIES: dict[str, Study] = {
    "operators": Study(
        name="operators",
        reference=Reading("paper", "zero-mean GP (Table I)", "zero-mean"),
        readings=(
            Reading("operator-unit", "unit variance (v4)", "unit"),
            Reading("operator-signal", "per-axis signal (v5)", "signal"),
            Reading("operator-correlation", "correlation only", "correlation"),
        ),
        methods=("dist-gprl",),
        question=(
            "Is a claim the paper's, or one reading of K_tt in the covariance operator "
            "S = K (K + lambda I)^-1 the paper leaves open?"
        ),
    )
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


def studies_of(reference_preset: str) -> tuple[Study, ...]:
    """The studies read beside ``reference_preset``'s Table I."""
    return tuple(s for s in STUDIES.values() if s.reference.preset == reference_preset)
