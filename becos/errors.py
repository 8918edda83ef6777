"""Errors that name the file, the problem and the fix."""

from __future__ import annotations

from pathlib import Path


class BecosError(Exception):
    """Base class of every error becos raises on purpose."""


class InputFileError(BecosError):
    """A file given to becos is missing, unreadable or inconsistent.

    The message always reads ``<file>: <problem>. Fix: <fix>`` so a user knows where to look.
    """

    def __init__(self, path: str | Path, problem: str, fix: str):
        self.path = Path(path)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.path}: {problem}. Fix: {fix}")


class ConfigError(BecosError):
    """A configuration value is missing, of the wrong type or inconsistent."""
