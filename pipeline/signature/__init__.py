"""The signature wing: ``signature.json``, its checks, and what reads a session's signature.

:mod:`~pipeline.signature.checks` validates a document (schema, numbers, rigid frames);
:mod:`~pipeline.signature.file` writes it from the committed identification stages and
reads it back, refusing a stale one.
"""
