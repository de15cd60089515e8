"""A logger's stand-in for tests that drive the node's parts without ROS."""

from __future__ import annotations


class LogLines:
    """Keeps what is logged (info, warning, error alike) in `lines`, in order."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)

    warning = error = info
