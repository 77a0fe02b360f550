"""Network unit blocks in amaranth.sim against independent references (spec net.md §1.1,
§5.2 "Unit"): Crc32 against ``zlib.crc32`` (check value, lengths 0..80 and full frames, 1, 4
and 8 bytes per beat with partial last beats, the good-frame residue), InternetChecksum
against scapy's ``checksum`` (RFC 1071; odd lengths, a preset pseudo-header sum)."""

import random
import zlib

import pytest
from scapy.utils import checksum as scapy_checksum

from hdl.net import Crc32, InternetChecksum
from hdl.params import ParameterError

from .streamsim import simulate


def crc_of(data_bytes, messages):
    """Run ``messages`` (bytes) through a Crc32; return each one's ``crc`` and residue
    flag after its last beat."""
    dut = Crc32(data_bytes)
    out = []

    async def bench(ctx):
        for msg in messages:
            ctx.set(dut.clear, 1)
            await ctx.tick()
            ctx.set(dut.clear, 0)
            for i in range(0, len(msg), data_bytes):
                chunk = msg[i:i + data_bytes]
                ctx.set(dut.data, int.from_bytes(chunk.ljust(data_bytes, b"\x5a"), "little"))
                ctx.set(dut.count, len(chunk))
                ctx.set(dut.valid, 1)
                await ctx.tick()
            ctx.set(dut.valid, 0)
            await ctx.tick()
            out.append((ctx.get(dut.crc), ctx.get(dut.residue_ok)))

    simulate(dut, bench)
    return out


@pytest.mark.parametrize("data_bytes", [1, 4, 8])
def test_crc32_matches_zlib(data_bytes):
    rng = random.Random(data_bytes)
    messages = [b"123456789", b""] + [rng.randbytes(n) for n in range(1, 40)]
    messages += [rng.randbytes(n) for n in (60, 64, 1514)]
    got = crc_of(data_bytes, messages)
    assert got[0][0] == 0xCBF43926
    for msg, (crc, _) in zip(messages, got):
        assert crc == zlib.crc32(msg), (len(msg), hex(crc), hex(zlib.crc32(msg)))


def test_crc32_residue_of_good_frames():
    rng = random.Random(5)
    frames = [rng.randbytes(n) for n in (60, 61, 100, 1514)]
    good = [f + zlib.crc32(f).to_bytes(4, "little") for f in frames]
    bad = [g[:-1] + bytes([g[-1] ^ 0x01]) for g in good]
    got = crc_of(1, good + bad)
    assert [r for _, r in got] == [1] * len(good) + [0] * len(bad)
    assert all(crc == 0x2144DF1C for crc, _ in got[:len(good)])


def test_internet_checksum_matches_scapy():
    rng = random.Random(7)
    messages = [rng.randbytes(n) for n in list(range(0, 24)) + [1499, 1500]]
    presets = [0, 0x1234, 0xFFFF]
    dut = InternetChecksum()
    got = []

    async def bench(ctx):
        for n, msg in enumerate(messages):
            ctx.set(dut.preset, presets[n % 3])
            ctx.set(dut.clear, 1)
            await ctx.tick()
            ctx.set(dut.clear, 0)
            for byte in msg:
                ctx.set(dut.data, byte)
                ctx.set(dut.valid, 1)
                await ctx.tick()
            ctx.set(dut.valid, 0)
            await ctx.tick()
            got.append(ctx.get(dut.checksum))

    simulate(dut, bench)
    for n, (msg, value) in enumerate(zip(messages, got)):
        preset = presets[n % 3]
        # scapy sums the preset as two leading bytes (one's complement addition commutes)
        want = scapy_checksum(preset.to_bytes(2, "big") + msg)
        assert value == want, (len(msg), hex(preset), hex(value), hex(want))


def test_bad_parameter_names_the_value():
    with pytest.raises(ParameterError, match="data_bytes must be an integer in 1..16, not 0"):
        Crc32(0)
