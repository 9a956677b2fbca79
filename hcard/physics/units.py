"""Former name of :mod:`hcard.quantities`, kept for plugins that import it from here."""

from hcard.quantities import (
    UnitError,
    display_unit,
    format_value,
    parse_quantity,
    parse_unit,
)

__all__ = ["UnitError", "display_unit", "format_value", "parse_quantity", "parse_unit"]
