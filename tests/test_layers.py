"""The package's import layers (DESIGN §1), read from every module's source with `ast`.

Every ``import`` and ``from ... import`` counts, including those inside functions (a lazy
import is still a dependency). ``from a.b import c`` depends on module ``a.b.c`` if that is a
module, else on ``a.b``; importing a submodule does not count as depending on its package's
``__init__``.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "distgprl"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


@cache
def modules() -> dict[str, Path]:
    """Every module of the package: dotted name -> file."""
    return {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


@cache
def imports(name: str) -> frozenset[str]:
    """Absolute names of everything module ``name`` imports (top-level packages for
    third-party imports, full module names inside distgprl)."""
    tree = ast.parse(modules()[name].read_text(), filename=str(modules()[name]))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative imports are not used in this package
                base = name.rsplit(".", node.level)[0]
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            for alias in node.names:
                child = f"{target}.{alias.name}"
                out.add(child if child in modules() else target)
    return frozenset(out)


def importers(prefix: str) -> list[str]:
    """The modules in package ``prefix`` (e.g. ``distgprl.sim``) and the module itself."""
    return [m for m in modules() if m == prefix or m.startswith(prefix + ".")]


def offending(prefix: str, forbidden: tuple[str, ...]) -> list[str]:
    """``module -> import`` lines of modules under ``prefix`` importing a forbidden name."""
    assert importers(prefix), f"no module {prefix}"
    found = []
    for module in importers(prefix):
        for target in sorted(imports(module)):
            if any(target == f or target.startswith(f + ".") for f in forbidden):
                found.append(f"{module} -> {target}")
    return found


def test_the_parser_sees_lazy_and_from_imports():
    """The reader finds a function-local import and resolves ``from pkg import module``: it
    would otherwise pass every rule below vacuously."""
    assert len(modules()) > 50
    assert "distgprl.sim.tasks" in imports("distgprl.sim.render")  # from ... import get_task
    assert "distgprl.skill.demos" in imports("distgprl.sim.render")  # lazy, in a function
    assert "pybullet" in imports("distgprl.sim.bullet")
    assert "torch" in imports("distgprl.agents.sac")


@pytest.mark.parametrize(
    "layer", ["distgprl.skill", "distgprl.safety", "distgprl.envs", "distgprl.sim"]
)
def test_lower_layers_do_not_import_experiments(layer):
    """skill/, safety/, envs/ and sim/ never import distgprl.experiments."""
    assert offending(layer, ("distgprl.experiments",)) == []


def test_no_import_between_envs_and_agents():
    """envs/ and agents/ both depend on the adaptation core and the method registry, not on
    each other, in either direction."""
    assert offending("distgprl.envs", ("distgprl.agents",)) == []
    assert offending("distgprl.agents", ("distgprl.envs",)) == []


@pytest.mark.parametrize("layer", ["distgprl.skill", "distgprl.safety"])
def test_skill_and_safety_never_import_pybullet(layer):
    assert offending(layer, ("pybullet", "pybullet_utils", "distgprl.sim")) == []


def test_sim_never_imports_torch():
    assert offending("distgprl.sim", ("torch", "stable_baselines3", "distgprl.agents")) == []


@pytest.mark.parametrize(
    "module",
    [
        "distgprl.version",
        "distgprl.io",
        "distgprl.errors",
        "distgprl.schema",
        "distgprl.identity",
        "distgprl.methods",
        "distgprl.studies",
        "distgprl.limits",
        "distgprl.config",
        "distgprl.config_checks",
        "distgprl.reward_scale",
        "distgprl.trial_protocol",
        "distgprl.data",
        "distgprl.adaptation",
    ],
)
def test_ground_floor_imports_nothing_above_it(module):
    """The shared modules every layer may use import no simulator, learner, env, experiment,
    hardware or report code."""
    assert module in modules()
    forbidden = (
        "torch",
        "stable_baselines3",
        "pybullet",
        "pybullet_utils",
        "gymnasium",
        "distgprl.sim",
        "distgprl.agents",
        "distgprl.envs",
        "distgprl.experiments",
        "distgprl.hardware",
        "distgprl.report",
        "distgprl.cli",
    )
    assert offending(module, forbidden) == []


@pytest.mark.parametrize("module", ["distgprl.io", "distgprl.version"])
def test_io_uses_only_the_standard_library(module):
    """distgprl.io and distgprl.version are the ground floor: no third-party or package
    import at all."""
    import sys

    assert {name.split(".")[0] for name in imports(module)} <= set(sys.stdlib_module_names)


def test_hardware_never_imports_experiments():
    """The hardware trials run whatever policy they are given (`hardware.trials.PolicyLoader`):
    no module of hardware/ imports experiments/, nor the safety layer below both."""
    assert offending("distgprl.hardware", ("distgprl.experiments",)) == []
    assert offending("distgprl.safety_layer", ("distgprl.experiments", "distgprl.hardware")) == []


def test_experiments_reach_hardware_through_the_twin_trials_only():
    """One direction and one door: experiments/ imports hardware/ only where a sweep runs
    Table II's twin trials (`experiments.table2_trials`, passing its policy loader in); the
    simulated evaluations use the safety layer (`distgprl.safety_layer`) below both."""
    assert "distgprl.safety_layer.gates" in imports("distgprl.experiments.safety_layer_evaluation")
    doors = {
        line.split(" -> ")[0] for line in offending("distgprl.experiments", ("distgprl.hardware",))
    }
    assert doors == {"distgprl.experiments.table2_trials"}


def test_report_does_not_import_the_runner_or_hardware():
    """report/ reads results through the schema and identity modules."""
    assert offending("distgprl.report", ("distgprl.experiments", "distgprl.hardware")) == []


def find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One cycle of ``graph`` as a path ``[a, b, ..., a]``, or [] if it is acyclic."""
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        stack.append(node)
        for child in sorted(graph.get(node, ())):
            if state.get(child) == 1:
                return stack[stack.index(child) :] + [child]
            if child not in state:
                cycle = visit(child)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = 2
        return []

    for node in sorted(graph):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return []


def test_find_cycle_finds_one():
    """The cycle finder is not vacuous: it reports a three-module circle and accepts a DAG."""
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == []


def test_no_import_cycle_inside_sim():
    """No circle among the sim/ modules (e.g. experts <-> tasks.dbm)."""
    sim = set(importers("distgprl.sim"))
    graph = {m: {t for t in imports(m) if t in sim and t != m} for m in sim}
    assert find_cycle(graph) == []


def package_graph() -> dict[str, set[str]]:
    """Every distgprl module -> the package modules it imports (top-level, in a function or
    under ``TYPE_CHECKING``: each is an edge)."""
    return {m: {t for t in imports(m) if t in modules() and t != m} for m in modules()}


def test_no_import_cycle_in_the_package():
    """No circle among all the package's modules, counting every import, lazy ones and the
    package's own lazy re-export of the API (``distgprl`` -> ``distgprl.api``) included: e.g.
    not sweep <-> follow_ups over `Job` (now `distgprl.experiments.jobs`), nor ``distgprl`` ->
    api -> ... -> schema -> ``distgprl`` over the version (now `distgprl.version`)."""
    graph = package_graph()
    assert "distgprl.api" in graph["distgprl"]  # the lazy __getattr__ is seen
    assert "distgprl.experiments.jobs" in graph["distgprl.experiments.follow_ups"]
    assert find_cycle(graph) == []


def test_cli_never_imports_the_simulator():
    """The CLI parses and calls library functions (`distgprl.experiments`, `distgprl.api`,
    ...); none of its modules imports distgprl.sim, at the top or inside a command."""
    assert "distgprl.experiments.skills" in imports("distgprl.cli.skills")  # lazy, in `hap`
    assert offending("distgprl.cli", ("distgprl.sim",)) == []


#: The package's layers, lowest first (docs/DESIGN.md §1): top-level modules or subpackages.
LAYERS: tuple[frozenset[str], ...] = tuple(
    frozenset(layer)
    for layer in (
        (
            "distgprl",
            "version",
            "io",
            "errors",
            "data",
            "config",
            "config_checks",
            "config_types",
            "reward_scale",
            "trial_protocol",
            "methods",
            "studies",
            "limits",
            "schema",
            "identity",
            "runstate",
            "machine",
        ),
        ("skill", "safety", "adaptation"),
        ("sim",),
        ("envs", "agents"),
        ("safety_layer",),
        ("hardware",),
        ("experiments",),
        ("report",),
        ("cli", "api", "__main__"),
    )
)


def layer_of(module: str) -> int:
    parts = module.split(".")
    key = parts[1] if len(parts) > 1 else "distgprl"
    for index, layer in enumerate(LAYERS):
        if key in layer:
            return index
    raise AssertionError(f"{module}: not in any layer of LAYERS (add it to DESIGN §1 too)")


def test_imports_point_down_the_layers():
    """Every distgprl module imports package modules of its own layer or lower ones only."""
    assert "distgprl.envs" in imports("distgprl")  # the exceptions below are seen
    upward = []
    for module in modules():
        for target in sorted(imports(module)):
            if (module, target) in {("distgprl", "distgprl.api"), ("distgprl", "distgprl.envs")}:
                # the two ways up, both lazy: the package's public API (its __getattr__) and
                # the gymnasium ids (distgprl.envs imports only the standard library until
                # gymnasium loads)
                continue
            if target.split(".")[0] == "distgprl" and layer_of(target) > layer_of(module):
                upward.append(f"{module} -> {target}")
    assert upward == []
