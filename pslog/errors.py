"""The one exception base of pslog.

Every failure a user can cause (bad file, bad value, bad rig) raises a subclass of
:class:`PslogError` with a one-line message naming the offending value; the CLI turns it
into ``error: <message>`` on stderr and exit code 1.
"""


class PslogError(Exception):
    """Base of every error pslog raises on purpose."""


class RigError(PslogError):
    """A rig or camera description is malformed or inconsistent."""


class LogFormatError(PslogError):
    """A file is missing, not an MCAP, not a pslog session, or damaged."""


class InputError(PslogError):
    """A user-supplied table (CSV, points) or argument value is malformed."""


class FusionError(PslogError):
    """A fusion method cannot run on the given rig or detections."""


class OutputExistsError(PslogError):
    """An output file exists and ``--force`` was not given."""
