"""The FMI status codes (the same numbers in FMI 2.0 and 3.0) and their names: the one table the
adapters, the launcher's messages and the host-side tools read."""
OK, WARNING, DISCARD, ERROR, FATAL, PENDING = range(6)
NAMES = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")  # PENDING: FMI 2.0 only


def status_name(status) -> str:
    """``"ERROR"`` for 3; an unknown code as its number."""
    try:
        return NAMES[int(status)]
    except (IndexError, TypeError, ValueError):
        return str(status)


def log_category(status) -> str:
    """The log category of a message of that status: ``logStatusWarning`` ..., ``logAll`` for OK."""
    return "logAll" if int(status) == OK else f"logStatus{status_name(status).capitalize()}"
