"""Checks of user input shared by the library and the command line.

Every check raises :class:`InputError` (or a subclass: ``DesignError``, ``ImageError``,
``HeightMapError``) whose message names the field or option and the rule it breaks. The
command line turns any ``InputError`` into ``error: <message>`` and exit code 2, before
any work is done.
"""

from __future__ import annotations


class InputError(ValueError):
    """Input that cannot be used; the message names the field or option and the rule."""
