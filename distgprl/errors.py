"""User-facing errors: the CLI turns these into one clear line and exit code 2."""


class UserInputError(Exception):
    """Bad input from the user (file, name, option). The message is the whole explanation."""
