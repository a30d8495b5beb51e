"""The two kinds of failure a command reports, by exit status.

Raised anywhere below the command line; ``viewer.cli`` turns them into one
message on stderr and the exit status (2 for usage, 1 for anything else).
"""


class UsageError(Exception):
    """Bad usage detected after parsing: exit 2."""


class Failure(Exception):
    """Any other failure: exit 1."""
