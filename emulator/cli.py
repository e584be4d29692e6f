"""`navtwin emulate`."""


def register(sub) -> None:
    """Filled in by the emulator runtime."""
