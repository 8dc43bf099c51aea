"""The browser viewer as the commands open and keep it: a scene on ``--host``/``--port``, served until Ctrl-C."""

from __future__ import annotations

import argparse
import sys
import threading


def scene(args: argparse.Namespace, rec, model, *, settings, truth=None, quiet: bool = False):
    """A viewer scene of ``rec``'s cameras and ``model`` on a server at ``--host``/``--port``, with the
    joints of ``truth`` (truth.npz arrays) when given; ``quiet``: a server only to record from, which says
    nothing (:func:`tracker.viewer.scene.start_server`)."""
    from tracker.viewer.scene import Scene, start_server

    server = start_server(args.host, args.port, quiet=quiet)
    names = None if truth is None else list(truth["joint_names"])
    return Scene(server, model, rec.cameras, settings.solve.robust_c, names)


def serve(message: str, *closing) -> int:
    """Keep the viewer up until Ctrl-C (then exit 0: everything is already written)."""
    print(f"{message}; press Ctrl-C to quit", file=sys.stderr, flush=True)
    stop = threading.Event()
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    for item in closing:
        item.close()
    return 0
