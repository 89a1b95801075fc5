"""decoderwords: what native code writes on descriptor 2 caught, line by line, and descriptor 2
given back, also when the block raises."""

from __future__ import annotations

import os

import pytest


def test_native_stderr_catches_fd_2_and_gives_it_back(capfd):
    """What is written to descriptor 2 inside is caught, line by line; after, descriptor 2 is
    the real stderr again, also when the block raises."""
    from scalematch.decoderwords import native_stderr

    with native_stderr() as said:
        os.write(2, b"libpng warning: iCCP: too short\n\nsecond line\n")
        assert said == []  # filled once the block ends
    assert said == ["libpng warning: iCCP: too short", "second line"]
    with pytest.raises(RuntimeError):
        with native_stderr() as said:
            os.write(2, b"inside\n")
            raise RuntimeError("the block failed")
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"
