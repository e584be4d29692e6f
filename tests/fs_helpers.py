"""Making writes fail on purpose, for the tests of full disks."""
import resource
import signal


def fsize_limit(nbytes: int):
    """A preexec_fn: files of the child may not grow past *nbytes* (RLIMIT_FSIZE)."""
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes fail with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return limit
