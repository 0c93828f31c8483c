"""Errors that skyref raises for bad input.

Every invalid value is reported *before* any work starts, with the parameter's name, the
value that was given and the range that would have been accepted.
"""

__all__ = ["MAX_ECHO", "ParameterError", "SkyrefSetupError"]


#: Longest echo of a value in an error message, characters.
MAX_ECHO = 200


def _shortened(text: str) -> str:
    """``text`` cut to about MAX_ECHO characters, saying how long it was."""
    if len(text) <= MAX_ECHO:
        return text
    return f"{text[:MAX_ECHO - 40]}... ({len(text):,} characters)"


class ParameterError(ValueError):
    """A parameter is out of its valid range (or of the wrong kind).

    The message always reads ``<name> = <value>: <what is wrong> (valid: <range>)``.
    """

    def __init__(self, name: str, value, valid: str, problem: str = "invalid value"):
        self.name = name
        self.value = value
        self.valid = valid
        self.problem = problem
        super().__init__(f"{name} = {_shortened(repr(value))}: {problem} (valid: {valid})")


class SkyrefSetupError(RuntimeError):
    """The machine lacks something skyref needs (e.g. a working libLLVM); the message says
    what to install."""
