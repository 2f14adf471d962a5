"""The exceptions of monovo: every error carries the message the ``monovo`` command prints."""


class Error(Exception):
    """Base class of monovo's errors."""


class FormatError(Error, ValueError):
    """Input that monovo cannot use: a malformed line (the message names the file and the
    line), a value out of range, an unknown option, a sequence without what an option needs."""


class FileError(Error, OSError):
    """A file or folder that does not exist or cannot be read."""
