"""The errors of the build: each message is one line (or a short list) meant for the user."""


class BuildError(Exception):
    """An FMU cannot be built or does not validate; the message says why."""


class ModelFileError(BuildError):
    """A mistake in a model file: the message names the file and the line (``file.py:12: ...``)."""
