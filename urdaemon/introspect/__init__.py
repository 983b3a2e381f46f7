"""Introspection of a running system: ``urdaemon list``, ``info``, ``hz`` and ``echo``'s options
(docs/introspection.md). The statistics (``rates``), the verdicts (``silence``) and the text
(``tables``) are pure; ``views``, ``hz`` and ``echo`` are their asyncio shells."""

__all__: list[str] = []
