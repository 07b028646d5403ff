"""Exceptions the command line turns into one-line messages: bad input (exit 2), a stopped run."""


class InputError(Exception):
    """Bad user input (study file, CSV, flag); the message names the file, field and value."""


class RunInterrupted(Exception):
    """A run stopped before it finished (Ctrl-C, or no worker left); the message says what is
    kept and how to resume. ``code`` is the exit code: 130 after Ctrl-C, 1 otherwise."""

    def __init__(self, message: str, code: int = 130):
        super().__init__(message)
        self.code = code
