"""``tracker eval``: MPJPE, PA-MPJPE, PCK@50mm and lost frames of a poses.npz against a truth.npz."""

from __future__ import annotations

import argparse

HELP = "MPJPE, PA-MPJPE, PCK@50mm and lost frames of poses.npz against truth.npz"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``tracker eval``: the poses and the truth."""
    parser.add_argument("poses")
    parser.add_argument("truth")


def run(args: argparse.Namespace) -> int:
    """Print the evaluation report."""
    from tracker.evaluate import evaluate, format_report
    from tracker.io.poses import load_poses

    print(format_report(evaluate(load_poses(args.poses), load_poses(args.truth))))
    return 0
