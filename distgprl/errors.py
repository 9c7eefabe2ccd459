"""User-facing errors: the CLI turns these into one clear line and exit code 2."""


class UserInputError(Exception):
    """Bad input from the user (file, name, option). The message is the whole explanation."""


class RunBusyError(UserInputError):
    """Another process holds the run folder's lock: it is training that run right now."""
