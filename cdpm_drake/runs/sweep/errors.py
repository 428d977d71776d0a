"""The error of a bad sweep file, variant or sweep run."""


class SweepError(ValueError):
    """A bad sweep file or variant; the message names the field (or variant) and the value."""
