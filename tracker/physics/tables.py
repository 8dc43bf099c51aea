"""Text tables of the physics experiments for ``tracker experiment``: ours beside the paper's."""

from __future__ import annotations

from tracker.physics import experiment as ex
from tracker.physics import insect


def superquadric_table(rows: list[dict]) -> list[str]:
    """Tables I-IV as one Markdown table: per (density, variance) our mean errors (``experiment.run``)
    and, after the slash, the paper's (``experiment.PAPER_TABLES``)."""
    lines = [
        "| density % | variance | "
        + " | ".join(f"{name} (ours / paper)" for name in ex.ERRORS)
        + " | node RMS | capped frames |",
        "|---" * (len(ex.ERRORS) + 4) + "|",
    ]
    for row in rows:
        paper = ex.PAPER_TABLES.get((row["density"], row["variance"]))
        cells = [f"{row[name]:.3g} / {paper[k]:g}" if paper else f"{row[name]:.3g}" for k, name in enumerate(ex.ERRORS)]
        lines.append(
            f"| {row['density']} | {row['variance']:g} | "
            + " | ".join(cells)
            + f" | {row['position_rms']:.3g} | {row['capped']} |"
        )
    return lines


def claims_lines(claims: list[tuple[str, bool, str]]) -> list[str]:
    """One line per claim of ``experiment.check_claims``: held or failed, and the detail."""
    return [f"- {'held' if held else 'FAILED'}: {claim} ({detail})" for claim, held, detail in claims]


def insect_table(results: dict[str, insect.Result]) -> list[str]:
    """Constraint violation and node position error of each insect run (``insect.Result.summary``)."""
    lines = [
        "| data | joint violation mean | joint violation max | position error mean | position error max |",
        "|---|---|---|---|---|",
    ]
    for name, result in results.items():
        s = result.summary
        lines.append(
            f"| {name} | {s['violation_mean']:.2g} | {s['violation_max']:.2g} | "
            f"{s['position_error_mean']:.3g} | {s['position_error_max']:.3g} |"
        )
    return lines
