"""A report's sections: each gives its result, or :class:`NotMeasurable` with the reason.

One section that cannot be computed for a design never takes the report down: the page
says "not measurable: <reason>" for that section, report.json holds
``{"not_measurable": "<reason>"}`` in its place, and every other section is written.

Which errors a section absorbs
------------------------------
Only :data:`MEASURING_ERRORS`, the errors of measuring a design that does not allow the
measurement: ``ValueError`` (an edge too blurred to find, a chart the design cannot
resolve, a derived design its own validation refuses: ``InputError`` and pydantic's
``ValidationError`` are ValueErrors too, as is numpy's ``LinAlgError``) and
``ArithmeticError`` (a division by zero, an overflow, numpy's ``FloatingPointError``).
Programming errors (``KeyError``, ``IndexError``, ``TypeError``, ``AttributeError``,
``NameError``, ...), ``OSError`` (the disk) and ``MemoryError`` are not absorbed: they take
the report down, so a test sees them.

A section that needs another section's result (the scans' computed RMTF folds the RMTF
section's line-spread functions; the parameter study's own row is the report's ghost
analysis and RMTF) is not measurable where that one is not (:func:`needs`), or computes
without it where it can.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

#: The errors a section absorbs (a design the measurement does not allow); any other
#: error propagates
MEASURING_ERRORS: tuple[type[Exception], ...] = (ValueError, ArithmeticError)

#: report.json's key for a section that could not be computed
KEY = "not_measurable"

T = TypeVar("T")


@dataclass(frozen=True)
class NotMeasurable:
    """A section that cannot be computed for this design, and why."""

    reason: str

    def to_dict(self) -> dict:
        """report.json's value for the section: ``{"not_measurable": reason}``."""
        return {KEY: self.reason}

    def __str__(self) -> str:
        return f"not measurable: {self.reason}"


def measure(compute: Callable[..., T], *args: Any, **kwargs: Any) -> T | NotMeasurable:
    """``compute(*args, **kwargs)``, or :class:`NotMeasurable` where it raises one of
    :data:`MEASURING_ERRORS` (its message is the reason); other errors propagate."""
    try:
        return compute(*args, **kwargs)
    except MEASURING_ERRORS as err:
        return NotMeasurable(reason_of_error(err))


def reason_of_error(err: BaseException) -> str:
    """An error as a reason: its message, or its type's name where it has none."""
    return str(err) or type(err).__name__


def needs(**sections: Any) -> NotMeasurable | None:
    """The first of ``sections`` (name=result) that is not measurable, as the reason of a
    section that needs it: "needs the RMTF section (not measurable: ...)"; None where
    every one was computed."""
    for name, res in sections.items():
        if isinstance(res, NotMeasurable):
            return NotMeasurable(f"needs the {name} section ({res})")
    return None


def measured(res: T | NotMeasurable) -> T | None:
    """``res``, or None where it is :class:`NotMeasurable`."""
    return None if isinstance(res, NotMeasurable) else res


def as_data(res: Any, convert: Callable[[Any], Any] | None = None) -> Any:
    """A section's result as report.json holds it: ``{"not_measurable": reason}`` where
    it is :class:`NotMeasurable`, None where the section was not run (None), else
    ``convert(res)``; without ``convert``, ``res.to_dict()`` where it has one, else
    ``res`` (already JSON-shaped)."""
    if res is None:
        return None
    if isinstance(res, NotMeasurable):
        return res.to_dict()
    if convert is not None:
        return convert(res)
    return res.to_dict() if hasattr(res, "to_dict") else res


def not_measurable(value: Any) -> str | None:
    """The reason a section of report.json (``value``) was not computed, or None where
    it was (for the readers of report.json: the page, the verdict, paper vs model)."""
    if isinstance(value, dict) and set(value) == {KEY}:
        return value[KEY]
    return None


def section(data: dict, key: str) -> Any:
    """Section ``key`` of report.json's ``data``; None where it is absent, null or not
    measurable."""
    value = data.get(key)
    return None if not_measurable(value) is not None else value
