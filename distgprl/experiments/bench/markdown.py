"""The benchmark results as Markdown tables (the documentation site's benchmarks page), from a
`run_benchmarks` JSON."""

from __future__ import annotations

from typing import Any

__all__ = ["markdown_table"]


def _fmt_ms(timing: dict[str, float], digits: int = 3) -> str:
    return (
        f"{timing['median_us'] / 1e3:.{digits}f} "
        f"({timing['p10_us'] / 1e3:.{digits}f}–{timing['p90_us'] / 1e3:.{digits}f})"
    )


def markdown_table(document: dict[str, Any]) -> str:
    """The benchmark results as Markdown tables (the site's benchmarks page), from a
    `run_benchmarks` JSON.

    Times are medians with the 10th–90th percentile range in parentheses, in ms.
    """
    a = document["adaptation"]
    machine = document["machine"]
    load = machine["load_average"]
    lines = [
        f"Machine: {machine['cpu']}, {machine['cores']} cores; 1-min load average "
        f"{load[0]:.2f} at start, {document['load_average_after'][0]:.2f} at end "
        f"({'quick' if document['quick'] else 'full'} run).",
        "",
        "| Adaptation compute (ms) | this package | paper (i7-1185G7) | naive, same run |",
        "|---|---|---|---|",
    ]
    naive_names = {
        "edf": ("edf_pybullet", "PyBullet getClosestPoints"),
        "gp_conditioning": ("gp_resolve", "GP re-solved"),
        "policy": ("policy_sb3_predict", "SB3 predict"),
    }
    labels = {
        "edf": f"EDF query ({a['points_queried']} points), per window",
        "gp_conditioning": "GP conditioning (S_W update + segment), per window",
        "policy": f"policy (SAC actor in NumPy, {a['observation_size']}-D obs), per window",
        "total": "total, per window",
    }
    for name, label in labels.items():
        naive = ""
        if name in naive_names:
            key, what = naive_names[name]
            naive = f"{_fmt_ms(a['naive_per_window'][key])} {what}"
            if name == "policy":
                naive += f"; {_fmt_ms(a['naive_per_window']['policy_torch_actor'])} torch actor"
        lines.append(
            f"| {label} | {_fmt_ms(a['per_window'][name])} | "
            f"{a['paper_ms_per_window'][name]:g} | {naive} |"
        )
    lines.append(
        f"| **total, per episode ({a['n_windows']} windows)** | **{_fmt_ms(a['per_episode'])}** | "
        f"{a['paper_ms_per_episode']:g} | {_fmt_ms(a['naive_per_episode'], 2)} |"
    )
    s = a["speedup"]
    lines += [
        "",
        f"Per episode: {s['episode_vs_paper']:.0f}× faster than the paper's figure, "
        f"{s['episode_vs_naive']:.0f}× faster than the naive pipeline; EDF "
        f"{s['edf_vs_pybullet']:.0f}× faster than PyBullet on the same points (interleaved, "
        f"max |difference| {a['edf_pybullet_max_abs_difference_m'] * 1e3:.3f} mm); GP conditioning "
        f"{s['gp_vs_resolve']:.0f}× faster than re-solving. Target ≤ "
        f"{a['target_ms_per_episode']:g} ms per episode: "
        f"{'met' if a['meets_target'] else 'NOT met'}. The environment's own timer (includes the "
        f"obstacle read from PyBullet) gives {_fmt_ms(a['in_env_per_window'])} ms per window.",
        "",
        "| Other | median (p10–p90) |",
        "|---|---|",
    ]
    for task, env in document.get("environment", {}).items():  # not in files before issue 29
        lines.append(
            f"| env step, {task}, process CPU, ms (over the bare physics in it) | "
            f"{env['env_step_cpu_ms']:.1f} ({env['env_step_over_bare_physics']:.2f}x) |"
        )
    sac = document["sac_step"]
    lines.append(
        f"| SAC gradient step, regularised actor loss (batch {sac['batch_size']}), ms | "
        f"{_fmt_ms(sac['regularised'], 2)} |"
    )
    lines.append(
        f"| SAC gradient step, plain SAC, ms | {_fmt_ms(sac['plain'], 2)} "
        f"(regularised / plain = {sac['regularised_over_plain']:.2f}) |"
    )
    if "cpu_regularised" in sac:  # not in benchmark files written before it was measured
        lines.append(
            f"| SAC gradient step, process CPU time, regularised / plain, ms | "
            f"{_fmt_ms(sac['cpu_regularised'], 2)} / {_fmt_ms(sac['cpu_plain'], 2)} "
            f"(ratio {sac['cpu_regularised_over_plain']:.2f}) |"
        )
    if "suite" in document:
        suite = document["suite"]
        lines.append(
            f"| paper suite ({len(suite['methods'])} methods x {len(suite['tasks'])} tasks x "
            f"{suite['seeds']} seeds), CPU-hours (hours on two idle cores) | "
            f"{suite['cpu_hours']:.1f} ({suite['hours_two_idle_cores']:.1f}) |"
        )
        if "floor" in suite:
            floor = suite["floor"]
            update = floor["sac_update"]
            physics = ", ".join(
                f"{task} {ms:.1f} ms" for task, ms in floor["physics_cpu_ms_per_step"].items()
            )
            lines.append(
                f"| its floor: matrix products of a plain SAC update "
                f"({update['matrix_products_ms']:.1f} ms, {update['gflop_per_update']:.2f} GFLOP "
                f"at {update['gflops']:.0f} GFLOP/s) + bare physics per step ({physics}), "
                f"CPU-hours (hours on two idle cores) | "
                f"{floor['cpu_hours']:.1f} ({floor['hours_idle_cores']:.1f}) |"
            )
            if "non_product_ms" in update:  # issue 49 on
                lines.append(
                    f"| plain SAC update, process CPU, ms: whole / matrix products / the rest "
                    f"(framework work) | {update['update_ms']:.1f} / "
                    f"{update['matrix_products_ms']:.1f} / {update['non_product_ms']:.1f} |"
                )
            ratio = document["ratios"].get("suite_over_floor")
            if ratio is not None:
                lines.append(f"| suite CPU-hours over its floor's | {ratio:.2f} |")
    return "\n".join(lines) + "\n"
