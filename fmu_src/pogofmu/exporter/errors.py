"""The errors of the build: each message is one line (or a short list) meant for the user."""


class BuildError(Exception):
    """An FMU cannot be built or does not validate; the message says why."""


class ModelFileError(BuildError):
    """A mistake in a model file: the message names the file and the line (``file.py:12: ...``)."""


class OutputError(BuildError):
    """The machine, not the model, failed the build: a file of the export cannot be written (disk
    full, no permission, a path under a file, ...). The message names the file and the reason;
    ``pogofmu export`` ends with exit status 1."""
