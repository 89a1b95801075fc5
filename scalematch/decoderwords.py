"""The decoders' own words: what libpng, libjpeg and libtiff write straight to the process's
stderr (file descriptor 2, past ``sys.stderr``; OpenCV gives no other way to hear them), caught
while a block runs (:func:`native_stderr`) and quoted once (:func:`decoder_words`), OpenCV's own
log silenced meanwhile (:func:`opencv_log_silenced`). Whether a decode catches them is
:func:`scalematch.imageio.catch_decoder_stderr`'s to say: off by default, as descriptor 2 belongs
to the whole process.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from typing import Any, Iterator, List, Optional, Tuple

import cv2

#: Most bytes of what the native decoders write on stderr during one decode that are read back:
#: libjpeg says only its first warning, libpng and libtiff one line before they give up.
NATIVE_TEXT_BYTES = 4096
#: Most lines of it quoted, and most characters of each.
NATIVE_LINES, NATIVE_LINE_CHARS = 3, 200
#: File descriptor 2 belongs to the whole process: one decode at a time has it redirected (a
#: block inside another, in the same thread, redirects it again and gives it back to the outer).
_STDERR_LOCK = threading.RLock()


@contextlib.contextmanager
def native_stderr() -> Iterator[List[str]]:
    """What native code writes on the process's stderr while the block runs (file descriptor 2,
    which the C libraries write to directly, past ``sys.stderr``): its lines, in the list
    yielded, filled once the block ends; none of it reaches the real stderr.

    Descriptor 2 is pointed at a file of no name meanwhile (:func:`_anonymous_file`) and set
    back after, whatever the block raises. It belongs to the whole process, so one thread at a
    time redirects it (the others wait): whatever another thread writes to it meanwhile is
    caught too. When it cannot be redirected (closed, or no such file can be made), the block
    runs as it is and the list stays empty.

    >>> with native_stderr() as said:
    ...     _ = os.write(2, b"libpng error: IDAT: CRC error\\n")
    >>> said
    ['libpng error: IDAT: CRC error']
    """
    said: List[str] = []
    with _STDERR_LOCK:
        redirected = _stderr_to_file()
        if redirected is None:
            yield said
            return
        sink, saved = redirected
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            with sink:
                sink.seek(0)
                text = sink.read(NATIVE_TEXT_BYTES).decode("utf-8", "replace")
            said.extend(line.strip() for line in text.splitlines() if line.strip())


def _stderr_to_file() -> Optional[Tuple[Any, int]]:
    """Point file descriptor 2 at a new file of no name: (the file, a duplicate of what
    descriptor 2 was); None, nothing changed, when there is no stderr or no such file."""
    try:
        sys.stderr.flush()  # Python's own text, written before, stays on the real stderr
    except (AttributeError, OSError, ValueError):
        pass
    try:
        sink = _anonymous_file()
    except OSError:
        return None
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to keep quiet
        sink.close()
        return None
    try:
        os.dup2(sink.fileno(), 2)
    except OSError:
        os.close(saved)
        sink.close()
        return None
    return sink, saved


def _anonymous_file() -> Any:
    """A new file of no name, opened to write and read bytes: in memory where the system makes
    one (``os.memfd_create``, Linux), else a temporary file (``tempfile``, whose imports would
    add 6 to 8 ms to the command line's start-up)."""
    if hasattr(os, "memfd_create"):
        try:
            return open(os.memfd_create("scalematch-stderr", os.MFD_CLOEXEC), "w+b")
        except OSError:  # not allowed here (a sandbox): the temporary file
            pass
    import tempfile

    return tempfile.TemporaryFile()


#: The prefixes libpng puts before its words (its default error and warning handlers).
_NATIVE_PREFIXES = ("libpng error: ", "libpng warning: ")


def decoder_words(lines: List[str]) -> str:
    """What a decoder said (:func:`native_stderr`'s lines) as one quotation: the first
    ``NATIVE_LINES`` distinct lines, each at most ``NATIVE_LINE_CHARS``, without libpng's
    prefixes; "" when it said nothing.

    >>> decoder_words(["libpng error: IDAT: CRC error"])
    '"IDAT: CRC error"'
    >>> decoder_words(["Corrupt JPEG data: premature end of data segment"] * 2 + ["Bogus"])
    '"Corrupt JPEG data: premature end of data segment; Bogus"'
    """
    out: List[str] = []
    for line in lines:
        for prefix in _NATIVE_PREFIXES:
            if line.startswith(prefix):
                line = line[len(prefix):]
        line = line[:NATIVE_LINE_CHARS]
        if line and line not in out:
            out.append(line)
    return f'"{"; ".join(out[:NATIVE_LINES])}"' if out else ""


@contextlib.contextmanager
def opencv_log_silenced() -> Iterator[None]:
    """OpenCV's log silenced while the block runs (its lines would be caught with the
    decoder's, as if the decoder said them), its level as it was after. The level is the
    process's: only under :func:`native_stderr`'s lock, so two threads do not each restore
    the other's silence."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)
