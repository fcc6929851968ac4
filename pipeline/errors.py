"""Error types. Every user-facing failure is an :class:`InputError` (exit code 2) whose message names
the file, the key or column, and what was expected; anything else is an internal error (exit code 1)."""

from __future__ import annotations


class InputError(Exception):
    """Bad input from the user: config, data or options. The CLI prints ``str(err)`` and exits 2."""

    def __init__(self, message: str, *, file: str | None = None, key: str | None = None):
        self.file = file
        self.key = key
        self.message = message
        where = ""
        if file and key:
            where = f"{file}: {key}: "
        elif file:
            where = f"{file}: "
        elif key:
            where = f"{key}: "
        super().__init__(where + message)


class ConfigError(InputError):
    """A problem in the YAML config (schema, expressions, names)."""


class DataError(InputError):
    """A problem in a data record (missing column, NaN, sampling...)."""


class SimulationError(InputError):
    """The model diverged or could not be simulated with the given parameters."""


class EstimationError(InputError):
    """An estimator cannot run on the given problem (singular regressors, bad weights, bad prior...)."""


class RefitAbandoned(EstimationError):
    """A refit whose error stayed above the model it extends for its whole simulation budget."""


def in_file(exc: InputError, file: str, key: str | None = None) -> InputError:
    """``exc`` naming ``file`` (and ``key`` before its own key, e.g. "structures" + "window") when it
    names no file: raised deep in a stage that does not know which config it serves. Same class."""
    if exc.file:
        return exc
    k = ".".join(p for p in (key, exc.key) if p) or None
    new = type(exc)(exc.message, file=file, key=k)
    new.__dict__.update({a: v for a, v in exc.__dict__.items() if a not in ("file", "key", "message")})
    return new
