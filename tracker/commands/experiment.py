"""``tracker experiment``: the physics paper's experiments, Tables I-IV (superquadric) or the insect."""

from __future__ import annotations

import argparse

from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "the physics paper's experiments: Tables I-IV, or the insect"

ABOUT = (
    "Run again the experiments of the physics paper the points tracker follows: the error analysis of its Tables "
    "I-IV (parts fitted at four data densities and four noise levels, printed beside the paper's values), or the "
    "insect tracked from dense and sparse points."
)
EXAMPLE = "tracker experiment superquadric"


def percentage_list(text: str) -> tuple[int, ...]:
    """Argument type: comma-separated percentages 1-100."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(0 < v <= 100 for v in values):
        raise argparse.ArgumentTypeError(f"must be percentages 1-100 separated by commas, e.g. 100,25, got {text}")
    return values


def variance_list(text: str) -> tuple[float, ...]:
    """Comma-separated variances; whole numbers stay ints so they print as the paper's 10, 5, 1, 0."""
    try:
        values = tuple(int(float(v)) if float(v).is_integer() else float(v) for v in text.split(","))
    except (ValueError, OverflowError):
        values = ()
    if not values or not all(0 <= v < float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"must be variances >= 0 separated by commas, e.g. 10,0, got {text}")
    return values


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker experiment``."""
    parser.add_argument(
        "name",
        choices=("superquadric", "insect"),
        help="superquadric: the error analysis of Tables I-IV (4 densities x 4 noise levels, "
        "beside the paper's values); insect: five parts and four joints tracked from dense "
        "and sparse points",
    )
    parser.add_argument(
        "--frames", type=options.positive_int, help="frames per run (default: 20 for superquadric, 36 for insect)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed of the data and noise (default 0)")
    parser.add_argument(
        "--densities",
        type=percentage_list,
        metavar="LIST",
        help="superquadric: comma-separated data densities in percent (default 100,75,50,25)",
    )
    parser.add_argument(
        "--variances",
        type=variance_list,
        metavar="LIST",
        help="superquadric: comma-separated noise variances (default 10,5,1,0)",
    )
    outputs = parser.add_argument_group("outputs")
    outputs.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Run the experiment and print its tables (or one JSON object with ``--json``)."""
    import json

    from tracker.physics import tables

    if args.name == "insect" and (args.densities or args.variances):
        raise TrackerInputError("--densities and --variances choose the superquadric grid; the insect has neither")
    if args.name == "superquadric":
        from tracker.physics import experiment

        densities = args.densities or experiment.DENSITIES
        variances = args.variances or experiment.VARIANCES
        frames_arg = {} if args.frames is None else {"frames": args.frames}
        progress = options.bar(args, None, "cell", leave=True)
        with progress(total=len(densities) * len(variances)) as bar:
            rows = experiment.run(densities, variances, seed=args.seed, progress=lambda row: bar.update(), **frames_arg)
        claims = experiment.check_claims(rows)
        if args.json:
            print(
                json.dumps(
                    {
                        "rows": rows,
                        "paper": {f"{d}/{v}": list(e) for (d, v), e in experiment.PAPER_TABLES.items()},
                        "errors": list(experiment.ERRORS),
                        "claims": [{"claim": c, "held": h, "detail": d} for c, h, d in claims],
                    },
                    indent=1,
                )
            )
        else:
            print("\n".join(tables.superquadric_table(rows) + ["", "claims:"] + tables.claims_lines(claims)))
        return 0
    from tracker.physics import insect

    frames = args.frames or insect.PERIOD
    results = {}
    for name, sparse in (("dense", False), ("sparse (7 points per part)", True)):
        with options.bar(args, name.split()[0], "frame", leave=True)(total=frames) as bar:
            results[name] = insect.run(sparse, frames=frames, seed=args.seed, progress=lambda *_: bar.update())
    if args.json:
        print(
            json.dumps(
                {
                    name: {**r.summary, "violation": r.violation.tolist(), "position_error": r.position_error.tolist()}
                    for name, r in results.items()
                },
                indent=1,
            )
        )
    else:
        print("\n".join(tables.insect_table(results)))
    return 0
