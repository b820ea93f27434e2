"""Exceptions shared by every stage (no heavy imports here)."""


class MotokError(Exception):
    """Base class of the errors that the CLI reports as one line (no traceback)."""


class InputError(MotokError, ValueError):
    """Bad user input: a file, field, frame or joint that cannot be used. The message names it."""


class HardwareError(MotokError):
    """A servo bus or servo failed; the message names the port or servo ID and the cause."""
