"""The one error type every imutool layer raises for bad input (shown as one line by the CLI)."""

from __future__ import annotations


class ImutoolError(Exception):
    """A user-facing error: the message names the file, the line/record and what is wrong."""

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None):
        where = ""
        if path is not None:
            where = f"{path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        super().__init__(where + message)
        self.path = path
        self.line = line
