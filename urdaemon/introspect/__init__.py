"""Introspection of a running system: ``urdaemon list``, ``info``, ``hz``, ``doctor`` and ``echo``'s
options (docs/introspection.md). The statistics (``rates``), the verdicts (``silence``) and the text
(``tables``) are pure; ``views``, ``hz`` and ``echo`` are their asyncio shells; ``doctor_command``
asks every robot's ``doctor`` service (its checks are doctor/'s, served by the daemon)."""

__all__: list[str] = []
