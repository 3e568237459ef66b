"""The engine's error types. Messages are written for the person who gave the input."""


class EngineError(Exception):
    """Base of every error the engine raises on purpose."""


class InvalidInput(EngineError, ValueError):
    """An input (file, array, parameter) cannot be used; the message says which and why."""


class RegistrationFailed(EngineError):
    """The input was valid but the registration could not produce a trustworthy answer."""
