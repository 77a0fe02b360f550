"""The signal names of an FST waveform file, read from its hierarchy block (written from the
format of GTKWave's ``fstapi.c``: block type, 8-byte length, then the block; the hierarchy
gzip- or LZ4-compressed; scopes, upscopes, attributes and variables as tagged records).
For tests that check what a waveform holds; values are not read."""

import struct
import zlib

__all__ = ["fst_signal_names"]

_HIER_GZ, _HIER_LZ4, _HIER_LZ4DUO = 4, 6, 7
_SCOPE, _UPSCOPE, _ATTR_BEGIN, _ATTR_END = 254, 255, 252, 253
_LAST_VAR_TYPE = 29


def _varint(data, pos):
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, pos


def _cstring(data, pos):
    end = data.index(b"\0", pos)
    return data[pos:end].decode(errors="replace"), end + 1


def _hierarchy(raw):
    pos = 0
    while pos < len(raw):
        kind = raw[pos]
        (length,) = struct.unpack_from(">Q", raw, pos + 1)
        block = raw[pos + 9:pos + 1 + length]
        pos += 1 + length
        if kind == _HIER_GZ:
            return zlib.decompress(block[8:], 16 + zlib.MAX_WBITS)
        if kind in (_HIER_LZ4, _HIER_LZ4DUO):
            import lz4.block
            (size,) = struct.unpack_from(">Q", block, 0)
            data = block[8:]
            if kind == _HIER_LZ4DUO:
                first, at = _varint(data, 0)
                data = lz4.block.decompress(data[at:], uncompressed_size=first)
            return lz4.block.decompress(data, uncompressed_size=size)
    raise ValueError("no hierarchy block in the FST file")


def fst_signal_names(path):
    """The full names (``scope.scope.name``) of every variable the FST file ``path`` records."""
    data = _hierarchy(open(path, "rb").read())
    names, scopes, pos = [], [], 0
    while pos < len(data):
        tag = data[pos]
        pos += 1
        if tag == _SCOPE:
            name, pos = _cstring(data, pos + 1)
            _, pos = _cstring(data, pos)
            scopes.append(name)
        elif tag == _UPSCOPE:
            scopes.pop()
        elif tag == _ATTR_BEGIN:
            _, pos = _cstring(data, pos + 2)
            _, pos = _varint(data, pos)
        elif tag == _ATTR_END:
            pass
        elif tag <= _LAST_VAR_TYPE:
            name, pos = _cstring(data, pos + 1)
            _, pos = _varint(data, pos)
            _, pos = _varint(data, pos)
            names.append(".".join([*scopes, name]))
        else:
            raise ValueError(f"FST hierarchy: unknown record {tag} at byte {pos - 1}")
    return names
