"""`navtwin host` and `navtwin replay`."""


def register(sub) -> None:
    """Filled in by the host service."""
