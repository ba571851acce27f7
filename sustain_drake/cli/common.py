"""What the sub-commands share: the user-facing error type and the exit codes."""

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3


class CliError(Exception):
    """A user-facing error: printed as one line on stderr, exit code 2, no traceback."""
