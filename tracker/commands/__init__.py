"""The ``tracker`` subcommands, one module each: ``HELP`` (its line in ``tracker --help``), ``ABOUT`` and ``EXAMPLE``
(what its own ``--help`` opens with: what it does, in plain words, and one command line), ``add_options(parser)`` and
``run(args)`` -> exit code.

Options several commands share live in :mod:`tracker.commands.options`, the viewer they open and keep
in :mod:`tracker.commands.viewing`.  Only :mod:`tracker.cli` and these modules import from here.
"""
