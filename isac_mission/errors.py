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


class PortInUseError(ConfigError):
    """A port this process must listen on is taken by another process. `port` is the port,
    `endpoint` what was to listen there (e.g. the Zenoh endpoint `tcp/127.0.0.1:7447`)."""

    def __init__(self, message: str, *, port: int, endpoint: str) -> None:
        super().__init__(message)
        self.port = port
        self.endpoint = endpoint
