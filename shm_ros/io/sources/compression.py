"""Decompression of what rosbag2 compresses (MCAP chunks, sqlite3 messages), with the error
types that mean "these bytes are damaged" (a reader turns them into a ``BagError`` naming the file).
"""

from __future__ import annotations

import types

from shm_ros.errors import InputError

ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def _zstd_module() -> types.ModuleType | None:
    try:
        from compression import zstd  # Python >= 3.14

        return zstd
    except ImportError:
        pass
    try:
        from backports import zstd  # what rosbags uses before 3.14

        return zstd
    except ImportError:
        return None


_ZSTD = _zstd_module()


def _zstd_error() -> type[Exception]:
    if _ZSTD is not None:
        return _ZSTD.ZstdError
    import zstandard

    return zstandard.ZstdError


#: Raised for damaged compressed data (zstd, or lz4 whose bindings raise ``RuntimeError`` only
#: from ``lz4.frame.decompress``, where nothing else can fail; see :func:`lz4_decompress`).
ZstdError: type[Exception] = _zstd_error()


class Lz4Error(InputError):
    """Damaged lz4 data."""


def zstd_decompress(data: bytes) -> bytes:
    """Every zstd frame of ``data``, decompressed."""
    if _ZSTD is not None:
        return _ZSTD.decompress(data)
    import zstandard

    return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 31)


def lz4_decompress(data: bytes) -> bytes:
    import lz4.frame

    try:
        return lz4.frame.decompress(data)
    except RuntimeError as exc:  # the lz4 bindings' only error type for bad frames
        raise Lz4Error(str(exc)) from exc
