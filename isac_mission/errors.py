"""Exception hierarchy. Pure code raises these with the bad value named; only service/ catches."""


class IsacError(Exception):
    """Base class of every error this package raises on purpose."""


class ConfigError(IsacError):
    """A scenario file is unreadable or invalid. The message lists one problem per line."""


class MessageError(IsacError):
    """A bus or wire message is malformed (bad JSON, wrong schema, non-finite numbers, ...)."""


class LinkError(IsacError):
    """A vehicle link failed (timeout, refused command, lost heartbeat)."""


class SolverError(IsacError):
    """A convex solver failed or returned a non-optimal status."""


class MissingDependencyError(IsacError):
    """An optional dependency is not installed. The message names the pip extra that brings it."""
