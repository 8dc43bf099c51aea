"""tracker experiment: the Tables I-IV grid and the insect through the command line, as tables and JSON."""

from __future__ import annotations

import json

import pytest

from tracker.cli import main
from tracker.physics import experiment


def test_superquadric_experiment_prints_ours_beside_the_paper(capsys) -> None:
    assert (
        main(["experiment", "superquadric", "--densities", "100", "--variances", "10,0", "--frames", "2", "--quiet"])
        == 0
    )
    lines = capsys.readouterr().out.splitlines()
    rows = [line for line in lines if line.startswith("| 100 |")]
    assert len(rows) == 2
    paper = experiment.PAPER_TABLES[(100, 10)]
    assert rows[0].startswith("| 100 | 10 |") and f"/ {paper[0]:g} |" in rows[0] and f"/ {paper[4]:g} |" in rows[0]
    claims = [line for line in lines if line.startswith("- ")]
    assert any("node-position error grows with noise" in line for line in claims)
    assert all(line.startswith(("- held:", "- FAILED:")) for line in claims)


def test_superquadric_experiment_json(capsys) -> None:
    assert (
        main(
            [
                "experiment",
                "superquadric",
                "--densities",
                "25",
                "--variances",
                "1",
                "--frames",
                "2",
                "--json",
                "--quiet",
            ]
        )
        == 0
    )
    report = json.loads(capsys.readouterr().out)
    (row,) = report["rows"]
    assert (row["density"], row["variance"]) == (25, 1)
    assert set(experiment.ERRORS) <= set(row) and all(row[name] >= 0 for name in experiment.ERRORS)
    assert report["paper"]["25/1"] == list(experiment.PAPER_TABLES[(25, 1)])
    assert report["errors"] == list(experiment.ERRORS)


def test_insect_experiment_json(capsys) -> None:
    assert main(["experiment", "insect", "--frames", "3", "--json", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    dense, sparse = report["dense"], report["sparse (7 points per part)"]
    assert len(dense["violation"]) == len(sparse["position_error"]) == 3
    assert dense["violation_max"] < 1e-5 and sparse["violation_max"] < 1e-5
    assert dense["position_error_mean"] < sparse["position_error_mean"]


@pytest.mark.parametrize("option, value", [("--densities", "0"), ("--densities", "a,b"), ("--variances", "-1")])
def test_bad_grid_options_are_usage_errors(option: str, value: str, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "superquadric", option, value])
    assert exit_.value.code == 2 and option in capsys.readouterr().err
