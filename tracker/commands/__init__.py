"""The ``tracker`` subcommands, one module each: ``HELP`` (its line in ``tracker --help``),
``add_options(parser)`` and ``run(args)`` -> exit code.

Options several commands share live in :mod:`tracker.commands.options`, the viewer they open and keep
in :mod:`tracker.commands.viewing`.  Only :mod:`tracker.cli` and these modules import from here.
"""
