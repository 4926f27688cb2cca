"""The one exception type for a user's mistake (a bad flag, file or scene): the `tamp` command line
prints its message on one line and exits with status 2. Any other exception is a bug and reaches
the user with its traceback.

A subclass of ValueError, so library callers that catch ValueError keep working. The libraries
below `tamp` (`learned`, `symbolic`) do not know this type: they raise ValueError for bad input,
and `is_user_error` counts those (raised by their own code, not deeper) as the user's, and so the
`guarded.InputError` of a file that failed the guarded reader or its schema, whoever read it, and the
`guarded.OutputError` of a file that could not be written (a full disk, a read-only folder)."""
from __future__ import annotations

import errno
from pathlib import Path

from guarded import InputError, OutputError

# a disk that takes no more (the write's OSError names no file): the user's to free, never a bug
DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EROFS)
# packages whose own ValueErrors are about their input (which the command line took from the user)
LIBRARIES = tuple(str(Path(__file__).resolve().parents[1] / name) for name in ("learned", "symbolic"))


class UserError(ValueError):
    """A mistake in what the user gave (flags, files, scenes), said in one line."""


def is_user_error(error: BaseException) -> bool:
    """UserError, InputError or OutputError; an OSError about a file (missing, unreadable) or a full disk; or a
    ValueError raised by the code of `learned` or `symbolic` themselves (their input checks), not by code they call."""
    if isinstance(error, (UserError, InputError, OutputError)):
        return True
    if isinstance(error, OSError) and (error.filename is not None or error.errno in DISK_FULL):
        return True
    if isinstance(error, ValueError) and error.__traceback__ is not None:
        tb = error.__traceback__
        while tb.tb_next is not None:
            tb = tb.tb_next
        return str(Path(tb.tb_frame.f_code.co_filename).resolve()).startswith(LIBRARIES)
    return False
