"""``tracker init``: place the first pose by hand in the browser viewer and save init.toml."""

from __future__ import annotations

import argparse
from pathlib import Path

from tracker.commands import options
from tracker.commands.viewing import scene, serve

HELP = "place the first pose by hand in the browser viewer and save init.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker init``."""
    parser.add_argument("recording", help="recording folder")
    parser.add_argument("--out", required=True, help="init.toml to write")
    parser.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    parser.add_argument("--init", help="pose to start from (default: the recording's init.toml, else the rest pose)")
    options.add_recording_options(parser)
    options.add_viewer_options(parser, record=False)


def run(args: argparse.Namespace) -> int:
    """Serve the placement until Ctrl-C (its save button writes ``--out``)."""
    from tracker.io.posefile import load_pose_file
    from tracker.model import rest_poses
    from tracker.track import Settings
    from tracker.viewer.placement import Placement, in_view

    rec, model = options.opened(args)
    start = Path(args.init) if args.init else rec.init_path
    poses = load_pose_file(start, model) if start is not None else rest_poses(model, in_view(rec.cameras))
    out = Path(args.out)
    Placement(scene(args, rec, model, Settings()), rec, model, poses, out)
    return serve(f"placing the first pose of {rec.path}; save writes {out}")
