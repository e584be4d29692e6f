"""common.signals: a stop handler run again inside its own first run (a second signal while
the first sets the event) returns at once instead of waiting for the event's lock."""
import threading

from navtwin.common.signals import stopper


def test_a_second_signal_inside_the_first_does_not_wait_for_the_lock():
    stop = threading.Event()
    handler = stopper(stop)
    real_set = stop.set

    def set_as_interrupted():
        with stop._cond:  # the first run holds the event's lock ...
            handler()  # ... when the second signal's run comes (between two bytecodes)
        real_set()

    stop.set = set_as_interrupted
    first = threading.Thread(target=handler, daemon=True)  # a handler that waits: no hang here
    first.start()
    first.join(10)
    assert not first.is_alive() and stop.is_set()
