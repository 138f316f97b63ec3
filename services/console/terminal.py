"""Reading single key presses from the terminal without blocking (POSIX termios, main thread).

`KeyReader` puts stdin in cbreak mode (no line buffering, no echo; Ctrl-C still raises
SIGINT) and always puts the saved settings back on exit, also after an exception. Without a
terminal it reads nothing.
"""
from __future__ import annotations

import os
import select
import sys


class KeyReader:
    def __init__(self, stream=None) -> None:
        self.stream = stream if stream is not None else sys.stdin
        self._saved = None
        self._fd = None

    def __enter__(self) -> "KeyReader":
        try:
            fd = self.stream.fileno()
        except (AttributeError, OSError, ValueError):
            return self
        if not os.isatty(fd):
            return self
        import termios
        import tty

        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd, termios.TCSANOW)
        return self

    def __exit__(self, *exc) -> None:
        self.restore()

    def restore(self) -> None:
        if self._saved is not None:
            import termios

            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    @property
    def active(self) -> bool:
        return self._saved is not None

    def read(self) -> str:
        """Whatever was typed since the last call ('' if nothing); never blocks."""
        if self._fd is None:
            return ""
        chunks = []
        while select.select([self._fd], [], [], 0)[0]:
            data = os.read(self._fd, 1024)
            if not data:
                break
            chunks.append(data)
        return b"".join(chunks).decode("utf-8", errors="ignore")
