"""Reading binary payloads out of the store without running code, in bounded memory (docs/security.md).

A database is input like any file: whoever can write a shared PostgreSQL store, or hands someone a
``.db`` file, chooses every byte of its BLOB columns. A pickle can name any importable callable and
have it called while it is read, so nothing that comes out of the store is unpickled freely.
Every BLOB that holds tensors (model weights, training checkpoints, SAC policies and replay buffers)
is read by :func:`load_tensors`: ``torch.load(weights_only=True)``, whose unpickler builds tensors,
numbers, strings, lists, tuples, dicts and a few torch types, and refuses any other global. Planner
checkpoints are JSON and raw float64 arrays (:func:`twisted.store.models.blob_to_array`), which
cannot name code.

Memory is bounded before anything is built: ``torch.save`` writes a zip archive whose members are all
stored uncompressed, so :func:`load_tensors` first reads the archive's directory alone and refuses a
compressed member (a few kilobytes could otherwise inflate to gigabytes) and members that add up to
more than the caller's bound; torch itself refuses a tensor whose declared size is not its member's
size. Once loaded, a tensor that claims more elements than its storage holds (a zero-stride view that
would turn one byte into billions on the first iteration) is refused too.
"""

from __future__ import annotations

from typing import Any

__all__ = ["UnsafePayloadError", "check_tensor_archive", "load_tensors", "stored_bytes"]


class UnsafePayloadError(ValueError):
    """A stored payload that is not plain data (tensors, numbers, strings, lists, dicts), or larger than
    what it declares: not loaded."""


def stored_bytes(data: object, what: str) -> bytes:
    """``data`` if it is bytes; :class:`UnsafePayloadError` naming ``what`` otherwise (SQLite keeps text or
    a number in a BLOB column as it was written, so a payload read back may be neither)."""
    if isinstance(data, bytes):
        return data
    if isinstance(data, bytearray | memoryview):
        return bytes(data)
    raise UnsafePayloadError(f"{what} cannot be loaded: it holds {type(data).__name__}, not bytes")


def check_tensor_archive(data: bytes, what: str, max_bytes: int | None = None) -> int:
    """The bytes the torch file ``data`` unpacks to, from its zip directory alone (nothing is inflated).

    Raises :class:`UnsafePayloadError` naming ``what`` for anything but a zip archive whose members are
    all stored uncompressed (what ``torch.save`` writes), or whose members add up to more than
    ``max_bytes``. A bare pickle or torch's legacy format is refused here: it is not what twisted
    stores, and reading it could run code.
    """
    import io
    import zipfile

    data = stored_bytes(data, what)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = archive.infolist()
    except Exception:  # noqa: BLE001 (arbitrary bytes: zipfile raises several kinds)
        raise UnsafePayloadError(
            f"{what} cannot be loaded: it is not a torch file (torch.save writes a zip archive); a bare "
            "pickle or torch's legacy format is never read, since reading it could run code"
        ) from None
    total = 0
    for member in members:
        if member.compress_type != zipfile.ZIP_STORED or member.compress_size != member.file_size:
            raise UnsafePayloadError(
                f"{what} cannot be loaded: its member {member.filename[:80]!r} is compressed "
                f"({member.compress_size:,} bytes that unpack to {member.file_size:,}); torch.save stores "
                "every member as it is, so it was made to expand: refused before anything is unpacked"
            )
        total += member.file_size
    if max_bytes is not None and total > max_bytes:
        raise UnsafePayloadError(
            f"{what} cannot be loaded: its members hold {total:,} bytes, more than the {max_bytes:,} "
            "its settings allow"
        )
    return total


def load_tensors(data: bytes, what: str, map_location: Any = "cpu", max_bytes: int | None = None) -> Any:
    """``torch.load(weights_only=True)`` of ``data``; :class:`UnsafePayloadError` naming ``what`` otherwise.

    Anything that is not a torch file of plain data, a crafted pickle included, is refused before a
    single object it names is built; so is an archive that would unpack to more than ``max_bytes``
    (:func:`check_tensor_archive`) and a tensor larger than its storage.
    """
    import io
    import re
    import warnings

    import torch

    check_tensor_archive(data, what, max_bytes)
    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols before it refuses
            warnings.simplefilter("ignore")
            loaded = torch.load(io.BytesIO(data), map_location=map_location, weights_only=True)
    except Exception as exc:  # noqa: BLE001 (the bytes are arbitrary: torch and pickle raise many kinds)
        text = " ".join(str(exc).split())
        named = re.search(r"GLOBAL (\S+) was not an allowed global", text)
        if "Weights only load failed" in text:
            found = f": it names {named.group(1)[:120]}" if named else ""
            reason = (
                "it holds more than tensors and plain data, and reading it could run code"
                f"{found}; refused (a stored payload is never unpickled freely)"
            )
        else:
            reason = f"it is not a readable torch payload ({type(exc).__name__}: {text[:200] or 'empty'})"
        raise UnsafePayloadError(f"{what} cannot be loaded: {reason}") from None
    _check_tensors(loaded, what)
    return loaded


def _check_tensors(loaded: Any, what: str) -> None:
    """Refuse a tensor that is not a plain dense one within its storage (walked without recursion)."""
    import torch

    stack = [loaded]
    while stack:
        value = stack.pop()
        if isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, (list, tuple, set, frozenset)):
            stack.extend(value)
        elif isinstance(value, torch.Tensor):
            if value.layout != torch.strided or value.is_meta:
                raise UnsafePayloadError(f"{what} cannot be loaded: it holds a {value.layout} tensor")
            claimed = value.numel() * value.element_size()
            if claimed > value.untyped_storage().nbytes():
                raise UnsafePayloadError(
                    f"{what} cannot be loaded: a tensor of shape {list(value.shape)[:8]} claims {claimed:,} "
                    f"bytes over a storage of {value.untyped_storage().nbytes():,}"
                )
