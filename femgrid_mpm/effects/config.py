"""Validation settings shared by every effect's scene keys."""

from pydantic import ConfigDict

#: unknown keys are errors; NaN and infinities are refused
EFFECT_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False, strict=False)
