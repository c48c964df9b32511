"""Reading binary payloads out of the store without running code (docs/security.md).

A database is input like any file: whoever can write a shared PostgreSQL store, or hands someone a
``.db`` file, chooses every byte of its BLOB columns. A pickle can name any importable callable and
have it called while it is read, so nothing that comes out of the store is unpickled freely.
Every BLOB that holds tensors (model weights, training checkpoints, SAC policies and replay buffers)
is read by :func:`load_tensors`: ``torch.load(weights_only=True)``, whose unpickler builds tensors,
numbers, strings, lists, tuples, dicts and a few torch types, and refuses any other global. Planner
checkpoints are JSON and raw float64 arrays (:func:`twisted.store.models.blob_to_array`), which
cannot name code.
"""

from __future__ import annotations

from typing import Any

__all__ = ["UnsafePayloadError", "load_tensors"]


class UnsafePayloadError(ValueError):
    """A stored payload that is not plain data (tensors, numbers, strings, lists, dicts): not loaded."""


def load_tensors(data: bytes, what: str, map_location: Any = "cpu") -> Any:
    """``torch.load(weights_only=True)`` of ``data``; :class:`UnsafePayloadError` naming ``what`` otherwise.

    Anything that is not a torch file of plain data, a crafted pickle included, is refused before a
    single object it names is built.
    """
    import io
    import re
    import warnings

    import torch

    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols before it refuses
            warnings.simplefilter("ignore")
            return torch.load(io.BytesIO(data), map_location=map_location, weights_only=True)
    except Exception as exc:  # noqa: BLE001 (the bytes are arbitrary: torch and pickle raise many kinds)
        text = " ".join(str(exc).split())
        named = re.search(r"GLOBAL (\S+) was not an allowed global", text)
        if "Weights only load failed" in text:
            found = f": it names {named.group(1)}" if named else ""
            reason = (
                "it holds more than tensors and plain data, and reading it could run code"
                f"{found}; refused (a stored payload is never unpickled freely)"
            )
        else:
            reason = f"it is not a readable torch payload ({type(exc).__name__}: {text[:200] or 'empty'})"
        raise UnsafePayloadError(f"{what} cannot be loaded: {reason}") from None
