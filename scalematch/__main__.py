"""``python -m scalematch`` and the ``scalematch`` command: the command line
(:mod:`scalematch.cli`), loaded here so that Ctrl-C while it loads (numpy, OpenCV and click:
the first 0.1 s or so) ends as it does later, with "interrupted" and exit 130, not a
traceback of the imports under way."""

import os
import sys

#: ``scalematch.exits.EXIT_INTERRUPTED`` (128 + SIGINT), which cannot be imported when this is
EXIT_INTERRUPTED = 130


def main() -> None:
    """Load the command line and run it."""
    try:
        from .cli import main as run
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        sys.stderr.flush()
        os._exit(EXIT_INTERRUPTED)  # a module half loaded is not finalised
    run()


if __name__ == "__main__":
    main()
