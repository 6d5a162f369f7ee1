"""The one error type users see.

Every mistake a user can make (a missing file, a malformed record, a bad option)
raises :class:`DynSlamError` with a message that names the file and, where it
applies, the record or line. The CLI turns it into a one-line message and a
non-zero exit; library code never prints or exits.
"""

from __future__ import annotations


class DynSlamError(Exception):
    """A user-facing error: bad input, bad option, unreadable file.

    The message is complete on its own (file, line or record, what was wrong).
    """
