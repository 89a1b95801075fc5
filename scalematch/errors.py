"""The words of an unexpected error, the same on the command line and in a batch line.

Imported by ``cli`` and ``batch`` when they start (nothing to import when memory has run out).
"""

from __future__ import annotations


def internal_error(exc: BaseException) -> str:
    """One line for an unexpected error: "internal error, " and what it was; "out of memory"
    for a ``MemoryError``, OpenCV's "Insufficient memory" or a C++ ``std::bad_alloc`` that
    OpenCV passes on.

    >>> internal_error(MemoryError())
    'internal error, out of memory (MemoryError)'
    >>> internal_error(RuntimeError("std::bad_alloc"))
    'internal error, out of memory (RuntimeError: std::bad_alloc)'
    >>> internal_error(RuntimeError("a bug\\non two lines"))
    'internal error, RuntimeError: a bug on two lines'
    """
    kind = type(exc).__name__
    kind = f"{type(exc).__module__}.{kind}" if type(exc).__module__ == "cv2" else kind
    text = " ".join(str(exc).split())  # OpenCV's messages span lines
    what = f"{kind}: {text}" if text else kind
    if isinstance(exc, MemoryError) or "Insufficient memory" in text or "bad_alloc" in text:
        what = f"out of memory ({what})"
    return f"internal error, {what}"


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` stands where a KeyboardInterrupt was: the interrupt is in its chain of
    causes and contexts (a library that fails while Ctrl-C unwinds it raises its own error,
    with the interrupt as its context), so Ctrl-C ends the run rather than being taken for an
    error of the pair.

    >>> try:
    ...     try:
    ...         raise KeyboardInterrupt
    ...     finally:
    ...         raise RuntimeError("release unlocked lock")
    ... except RuntimeError as exc:
    ...     print(interrupted(exc), interrupted(RuntimeError("a bug")))
    True False
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False
