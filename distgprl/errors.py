"""User-facing errors: the CLI turns these into one clear line and exit code 2."""


class UserInputError(Exception):
    """Bad input from the user (file, name, option). The message is the whole explanation."""


class RunBusyError(UserInputError):
    """Another process holds the run folder's lock: it is training that run right now."""


class ConfigError(UserInputError, ValueError):
    """A configuration that does not load (a preset, a ``--preset-file`` file or overrides): a
    key that is not one, a value of the wrong type or out of its range, or values that do
    not fit together. The message is one line naming the file and the key; ``key`` is the
    key's dotted name (``run.total_steps``, ``sac.lambda_sim``, ``tasks.dmb``), or empty when
    the file as a whole is wrong (not YAML, not a mapping, not found).

    A `ValueError` for Python callers, a `UserInputError` (exit code 2, one line) at the CLI.
    """

    def __init__(self, message: str, key: str = ""):
        super().__init__(message)
        self.key = key

    def __reduce__(self):
        """Pickled with its key (a sweep's worker processes send errors back)."""
        return (type(self), (str(self), self.key))
