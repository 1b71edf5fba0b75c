"""The reader's own chunk parser (recording._chunk_records, issue 31.3: mcap's field-by-field
reading was most of a recording's reading time) against the mcap library's ``breakup_chunk``,
the independent reference: the same records from every chunk of a real reference recording,
and, on the same chunks cut anywhere or with bytes overwritten, the same records or the same
error."""

from __future__ import annotations

import io
import random

import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from humanpt.runtime.recording import _chunk_data, _chunk_records
from tests.conftest import ROOT

REAL = ROOT / "recordings" / "arc_rsi" / "robot_gateway.mcap"  # 13 035 messages in 7 chunks


@pytest.fixture(scope="module")
def chunks() -> list[bytes]:
    """The decompressed records of each chunk of REAL, found by the mcap library's index."""
    data = REAL.read_bytes()
    with open(REAL, "rb") as f:
        idx = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    out = []
    for c in idx:
        rec = next(iter(StreamReader(io.BytesIO(data[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length]),
                                     skip_magic=True, emit_chunks=True).records))
        out.append(_chunk_data(rec))
    return out


def reference(data: bytes):
    """What mcap's breakup_chunk makes of ``data``: its records, or the type of its error."""
    try:
        return breakup_chunk(Chunk(compression="", data=data, message_start_time=0, message_end_time=0,
                                   uncompressed_crc=0, uncompressed_size=len(data)))
    except Exception as e:  # noqa: BLE001 (whatever it raises: the parser must raise the same)
        return type(e)


def ours(data: bytes):
    try:
        return _chunk_records(data)
    except Exception as e:  # noqa: BLE001
        return type(e)


def test_every_chunk_of_a_real_recording_reads_as_mcap_reads_it(chunks):
    assert len(chunks) == 7
    total = 0
    for data in chunks:
        want = reference(data)
        assert isinstance(want, list)
        assert ours(data) == want
        total += sum(isinstance(r, Message) for r in want)
    assert total == 13_035  # the recording's statistics (test_recording_damage.py's figure)


def test_a_chunk_cut_or_overwritten_reads_as_mcap_reads_it(chunks):
    """Every cut of the first chunk's first 600 bytes (its schemas, channels and first
    messages) and 300 seeded cuts and overwrites of the byte fields elsewhere: the same records
    or the same error as the mcap library."""
    first = chunks[0]
    for n in range(600):
        assert ours(first[:n]) == reference(first[:n]), n
    rng = random.Random(31)
    kinds = set()
    for _ in range(300):
        data = bytearray(rng.choice(chunks))
        at = rng.randrange(len(data))
        if rng.random() < 0.3:
            data = data[:at]
        else:
            data[at:at + 8] = rng.randbytes(8)
        want = reference(bytes(data))
        kinds.add("records" if isinstance(want, list) else want.__name__)
        assert ours(bytes(data)) == want, at
    assert "records" in kinds and len(kinds) > 1, kinds  # both outcomes were exercised
