"""The one exception type the client raises for everything that happens after arguments are accepted."""


class DistbandError(Exception):
    """A query that failed on the server, on the network, or whose reply stream broke the protocol.

    ``code`` is the gRPC status code's name (``"INVALID_ARGUMENT"``, ``"UNAUTHENTICATED"``, ``"UNAVAILABLE"``, ...)
    or ``"PROTOCOL"`` for a stream that does not follow distband.v1; ``details`` is the server's own message,
    which names the offending field (e.g. ``grid.padding``).
    Arguments the client can check itself raise ``ValueError`` / ``TypeError`` before connecting instead.
    """

    def __init__(self, code, details):
        super().__init__(f"{code}: {details}")
        self.code = code
        self.details = details
