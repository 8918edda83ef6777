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

    def __reduce__(self):
        # as the base class rebuilt (a subclass's own arguments differ): it crosses a process boundary
        # (the store writer's second process) with its path, problem and fix
        return InputFileError, (self.path, self.problem, self.fix)


class ConfigError(BecosError):
    """A configuration value is missing, of the wrong type or inconsistent."""


class DiskFullError(InputFileError):
    """A file could not be written because its disk (or quota) is full."""

    def __init__(self, path: str | Path, exc: OSError):
        import shutil

        try:
            free = f"{shutil.disk_usage(Path(path).parent).free} bytes free"
        except OSError:
            free = "free space unknown"
        super().__init__(
            path,
            f"cannot be written: {exc.strerror or 'no space left on device'} ({free} on its disk)",
            "free disk space, or set `results` to a folder on a larger disk, and run again: finished "
            "files are kept, so the run resumes where it stopped",
        )
