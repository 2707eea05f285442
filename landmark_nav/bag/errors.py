"""Errors raised by the bag subpackage."""


class BagError(Exception):
    """A bag could not be read or written; the message says what and where."""
