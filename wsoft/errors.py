"""Errors a user sees as one clear line (the CLI prints them and exits with code 2)."""

from __future__ import annotations


def suggestion(word: str, choices) -> str:
    """`` (did you mean a, b?)`` naming the choices closest to ``word`` (difflib), or ``""``."""
    import difflib

    close = difflib.get_close_matches(word, list(choices), n=3, cutoff=0.6)
    return f" (did you mean {', '.join(close)}?)" if close else ""


class WsoftError(Exception):
    """A problem with the user's input, worded for the user.

    ``file`` and ``prim`` name where the problem is; the message is printed as
    ``FILE: PRIM: message`` with no traceback by the CLI.
    """

    def __init__(self, message: str, *, file: str | None = None, prim: str | None = None):
        self.file = file
        self.prim = prim
        self.message = message
        super().__init__(self.line())

    def line(self) -> str:
        parts = [p for p in (self.file, self.prim) if p]
        parts.append(self.message)
        return ": ".join(parts)


class SceneError(WsoftError):
    """The USD stage cannot be turned into a scene (broken file, bad mesh, no light...)."""


class ParameterError(WsoftError):
    """An unknown technique, unknown parameter key or a bad parameter value."""


class DeclarationError(WsoftError):
    """A technique whose passes disagree with what it declares (:class:`wsoft.techniques.PassSpec`):
    a pass of an undeclared stage, or one reading or writing other kinds of resource."""


class NonFiniteWarning(RuntimeWarning):
    """A rendered channel holds NaN or inf values (counted in the stats; an EXR gets 0 there).
    The test suite turns it into an error."""
