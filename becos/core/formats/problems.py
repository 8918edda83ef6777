"""What the cheap structure checks of :mod:`becos.core.formats` raise, and the standard fixes."""

from __future__ import annotations

NAN_FIX = "re-export or re-download the mesh; becos cannot guess the positions"
TRUNCATED_FIX = "re-download or re-extract the dataset (the file is truncated or corrupt)"
NOT_A_FILE_FIX = "replace it with the mesh file itself (re-download or re-extract the dataset)"
LINK_FIX = "point the link at the real file, or put the file itself there"


class FormatProblem(ValueError):
    """A problem found by the cheap check whose fix is not 're-download a truncated file'."""

    def __init__(self, message: str, fix: str):
        super().__init__(message)
        self.fix = fix
