"""The one exception type for mistakes a user can make (bad files, options)."""


class TrackerInputError(Exception):
    """Bad input: the message names the file and the fix; the CLI exits with code 2."""
