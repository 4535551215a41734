"""How results print: ``repr`` of a result holding arrays or bytes shows their shapes, not their values.

A dataclass's generated ``repr`` prints every field, so a thumbnail printed its whole PNG and a
LOD level a summary of each array over several lines. Results holding arrays or bytes use
:func:`compact_repr` instead: one line, an array as its dtype and shape (``float32(1154, 3)``),
bytes as their length (``<48213 bytes>``), anything else as its own ``repr``.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["compact_repr"]


def _field_text(value: object) -> str:
    if isinstance(value, np.ndarray):
        shape = ", ".join(str(n) for n in value.shape) + ("," if value.ndim == 1 else "")
        return f"{value.dtype.name}({shape})"
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    return repr(value)


def compact_repr(self: object) -> str:
    """``Name(field=value, …)`` over the dataclass's fields shown in its repr, arrays and bytes
    by size. Assign it as the class's ``__repr__`` (a dataclass keeps a ``__repr__`` it is given)."""
    fields = ", ".join(f"{f.name}={_field_text(getattr(self, f.name))}"
                       for f in dataclasses.fields(self) if f.repr)  # type: ignore[arg-type]
    return f"{type(self).__name__}({fields})"
