"""``tracker eval``: MPJPE, PA-MPJPE, PCK@50mm and lost frames of a poses.npz against a truth.npz."""

from __future__ import annotations

import argparse

HELP = "MPJPE, PA-MPJPE, PCK@50mm and lost frames of poses.npz against truth.npz"

ABOUT = (
    "Compare tracked joints (poses.npz) with the true ones (truth.npz): the mean joint error in millimetres "
    "(MPJPE), the same after lining each frame's body up with the truth as a whole (PA-MPJPE), the share of "
    "joints within 50 mm of the truth (PCK@50mm) and the frames lost, overall and per joint. Every frame of the "
    "truth is scored, so frames the run did not track count as lost."
)
EXAMPLE = "tracker eval out/demo/poses.npz recordings/demo/truth.npz"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``tracker eval``: the poses and the truth."""
    inputs = parser.add_argument_group("inputs")
    inputs.add_argument("poses", metavar="POSES", help="poses.npz of a tracked run")
    inputs.add_argument("truth", metavar="TRUTH", help="truth.npz: the true joints of the same recording")


def run(args: argparse.Namespace) -> int:
    """Print the evaluation report."""
    from tracker.evaluate import evaluate, format_report
    from tracker.io.poses import load_poses

    print(format_report(evaluate(load_poses(args.poses), load_poses(args.truth))))
    return 0
