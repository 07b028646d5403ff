"""Exceptions that the command line turns into one-line messages and exit code 2."""


class InputError(Exception):
    """Bad user input (study file, CSV, flag); the message names the file, field and value."""
