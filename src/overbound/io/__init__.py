"""Readers and the epoch table."""

from overbound.io.geodesy import Reference
from overbound.io.open import FORMATS, read, sniff
from overbound.io.schema import COLUMNS, InputError, ReadReport, validate_epochs

__all__ = ["COLUMNS", "FORMATS", "InputError", "ReadReport", "Reference", "read", "sniff", "validate_epochs"]
