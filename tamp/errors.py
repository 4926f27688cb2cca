"""The one exception type for a user's mistake (a bad flag, file or scene): the `tamp` command line
prints its message on one line and exits with status 2. Any other exception is a bug and reaches
the user with its traceback.

A subclass of ValueError, so library callers that catch ValueError keep working. The libraries
below `tamp` (`learned`, `symbolic`) raise plain ValueError; the command line turns those into
UserError where it hands them a user's input (`tamp.app.cli.user_input`)."""


class UserError(ValueError):
    """A mistake in what the user gave (flags, files, scenes), said in one line."""
