"""Crafted and damaged recordings (issue 29, items 11 and 14): a chunk that declares 2 GiB is
refused before it is decompressed, damage in the first chunk hides nothing else, a recording
that cannot be read in full is never a MATCH, a deeply nested recorded config is one line.

The files are made with the mcap library from a real reference recording
(recordings/arc_rsi/robot_gateway.mcap: 13 035 messages in 7 chunks, as in the issue)."""

from __future__ import annotations

import io
import shutil
import struct
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import Writer

from humanpt.runtime.recording import MAX_CHUNK_BYTES, iter_entries, read
from humanpt.runtime.replay import EXIT_INCOMPLETE, EXIT_MATCH, EXIT_NOTHING_COMPARED, replay
from tests.conftest import ROOT, run_cli_here, run_measured

REAL = ROOT / "recordings" / "arc_rsi" / "robot_gateway.mcap"
FOOTER_TAIL = 1 + 8 + 20 + 8


def _chunks(path: Path) -> list[tuple[int, int, int]]:
    """(offset, record length with its 9-byte prefix, messages) of each chunk, by the mcap library."""
    with open(path, "rb") as f:
        idx = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = path.read_bytes()
    out = []
    for c in idx:
        rec = next(iter(StreamReader(io.BytesIO(data[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length]),
                                     skip_magic=True, emit_chunks=True).records))
        n = sum(isinstance(r, Message) for r in breakup_chunk(rec))
        out.append((c.chunk_start_offset, c.chunk_length, n))
    return out


def _message_count(path: Path) -> int:
    with open(path, "rb") as f:
        return make_reader(f).get_summary().statistics.message_count


def _zstd_bomb(size: int) -> tuple[bytes, int]:
    """(zstd frame of ``size`` zero bytes, their CRC), compressed as a stream (little memory)."""
    block = bytes(1 << 20)
    out = io.BytesIO()
    crc = 0
    with zstandard.ZstdCompressor().stream_writer(out, closefd=False) as w:
        for _ in range(size // len(block)):
            w.write(block)
            crc = zlib.crc32(block, crc)
    return out.getvalue(), crc


def _splice_chunk(src: Path, dst: Path, which: int, chunk: Chunk) -> int:
    """``src`` with its chunk number ``which`` replaced by ``chunk``; the footer's summary
    offsets and CRC follow the bytes that moved (the summary's chunk index offsets after the
    chunk are left stale). Returns the chunk's offset."""
    data = src.read_bytes()
    off, length, _ = _chunks(src)[which]
    b = RecordBuilder()
    chunk.write(b)
    new = b.end()
    delta = len(new) - length
    out = bytearray(data[:off] + new + data[off + length:])
    at = len(out) - FOOTER_TAIL
    start, offsets, _ = struct.unpack_from("<QQI", out, at + 9)
    start, offsets = start + delta, offsets + delta if offsets else 0
    struct.pack_into("<QQ", out, at + 9, start, offsets)
    crc = zlib.crc32(bytes(out[at:at + 25]), zlib.crc32(bytes(out[start:at])))
    struct.pack_into("<I", out, at + 9 + 16, crc)
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes(bytes(out))
    return off


@pytest.fixture(scope="module")
def bomb(tmp_path_factory) -> tuple[Path, int, int]:
    """The attack: a run directory whose robot_gateway.mcap has its third chunk replaced by a
    65 kB zstd chunk of 2 GiB of zeros that declares so (CRC right). (path, offset, messages lost)."""
    d = tmp_path_factory.mktemp("bomb") / "run"
    frame, crc = _zstd_bomb(2 << 30)
    assert 60_000 < len(frame) < 70_000  # the "65 kB zstd chunk"
    chunk = Chunk(compression="zstd", data=frame, message_start_time=0, message_end_time=0,
                  uncompressed_crc=crc, uncompressed_size=2 << 30)
    which = 2
    off = _splice_chunk(REAL, d / "robot_gateway.mcap", which, chunk)
    assert 500_000 < (d / "robot_gateway.mcap").stat().st_size < 540_000  # the 518 kB
    return d / "robot_gateway.mcap", off, _chunks(REAL)[which][2]


def test_a_chunk_declaring_2_gib_is_refused_before_it_is_decompressed(bomb):
    path, off, lost = bomb
    notes: list[str] = []
    entries = list(iter_entries(path, notes))
    # Every message of the other chunks is read (the chunks after it too).
    assert len(entries) == _message_count(REAL) - lost == 13035 - lost
    refused = [n for n in notes if f"chunk at offset {off}" in n]
    assert len(refused) == 1 and str(path) in refused[0] and "\n" not in refused[0]
    assert f"declares {2 << 30} bytes uncompressed" in refused[0] and f"{MAX_CHUNK_BYTES // 2**20} MiB" in refused[0]


def test_runs_info_and_replay_of_the_bomb_stay_small_and_say_so(bomb):
    path, off, _ = bomb
    # The issue: 2.19 GB and past 60 s each. Refused before decompression: the interpreter,
    # the libraries and the 518 kB file (a bound, not a timing: a hang is bounded by timeout).
    code, out, err, rss_kb = run_measured("runs", "info", str(path.parent))
    assert code == 1, out + err
    assert f"chunk at offset {off}" in out and "Traceback" not in err
    assert rss_kb < 400_000, rss_kb
    code, out, err, rss_kb = run_measured("replay", str(path))
    assert code == EXIT_INCOMPLETE, out + err
    assert "MATCH" not in out and "INCOMPLETE" in out and f"chunk at offset {off}" in out
    assert "Traceback" not in err
    assert rss_kb < 400_000, rss_kb


def test_damage_in_the_first_chunk_hides_only_that_chunk(tmp_path):
    """The issue: 1 of 13 035 messages read (the channels are declared only in the first chunk)
    and replay said MATCH, exit 0. The channels come from the summary: the other chunks read."""
    chunks = _chunks(REAL)
    off, length, first_n = chunks[0]
    data = bytearray(REAL.read_bytes())
    mid = off + length // 2  # inside its compressed data: a bad sector, the framing intact
    data[mid:mid + 64] = bytes(b ^ 0x5A for b in data[mid:mid + 64])
    path = tmp_path / "run" / "robot_gateway.mcap"
    path.parent.mkdir()
    path.write_bytes(bytes(data))
    rec = read(path)
    assert len(rec.entries) == 13035 - first_n > 10_000
    # Exactly the messages of the other chunks, on their topics and directions.
    rest = read(REAL).entries[first_n:]
    assert [(e.direction, e.topic, e.data) for e in rec.entries] == [(e.direction, e.topic, e.data) for e in rest]
    assert any(f"damaged chunk at offset {off}" in n for n in rec.notes), rec.notes
    assert any(f"{13035 - first_n} of the 13035 messages" in n for n in rec.notes), rec.notes
    # Replay: the messages before the damage are none, so nothing can be replayed (the core's
    # state after a gap is unknown): never a MATCH, says how much was read.
    res = replay(path)
    assert not res.match and res.exit_code == EXIT_NOTHING_COMPARED, res.report()
    assert res.messages_read == 13035 - first_n
    r = run_cli_here("replay", str(path))
    assert r.returncode == EXIT_NOTHING_COMPARED and "MATCH" not in r.stdout.replace("not a match", "")
    assert f"{13035 - first_n} messages read" in r.stdout and "Traceback" not in r.stderr
    r = run_cli_here("runs", "info", str(path.parent))
    assert r.returncode == 1 and f"damaged chunk at offset {off}" in r.stdout
    assert "robot_gateway/robot_state" in r.stdout


def test_a_damaged_middle_chunk_is_compared_up_to_it_and_is_not_a_match(tmp_path):
    chunks = _chunks(REAL)
    off, length, n = chunks[3]
    data = bytearray(REAL.read_bytes())
    data[off + length // 2:off + length // 2 + 64] = bytes(64)
    path = tmp_path / "robot_gateway.mcap"
    path.write_bytes(bytes(data))
    res = replay(path)
    before = sum(c[2] for c in chunks[:3])
    assert res.messages_read == 13035 - n
    assert res.exit_code == EXIT_INCOMPLETE and not res.match, res.report()
    assert res.inputs + res.recorded_outputs <= before and res.compared == res.recorded_outputs > 0
    assert "INCOMPLETE" in res.report() and "MATCH" not in res.report()
    assert replay(REAL).exit_code == EXIT_MATCH  # the file it was made from


def _rewrite(src: Path, dst: Path, run_meta: dict[str, str]) -> None:
    """``src`` written again with the mcap library, its ``humanpt.run`` metadata replaced."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        w = Writer(out)
        w.start(profile="humanpt", library="test")
        for m in reader.iter_metadata():
            w.add_metadata(m.name, run_meta if m.name == "humanpt.run" else m.metadata)
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for schema, channel, msg in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schema_ids:
                schema_ids[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channel_ids:
                channel_ids[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                             schema_ids.get(channel.schema_id, 0), channel.metadata)
            w.add_message(channel_ids[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.finish()


@pytest.mark.parametrize("where", ["config", "rig"])
def test_replay_of_deeply_nested_recorded_metadata_is_one_line(tmp_path, where):
    """Issue 29 item 14: a RecursionError traceback."""
    real = ROOT / "recordings" / "arc_rsi" / "controller.mcap"
    meta = dict(read(real).metadata)
    meta[where] = "[" * 200_000 + "]" * 200_000
    path = tmp_path / "controller.mcap"
    _rewrite(real, path, meta)
    r = run_cli_here("replay", str(path))
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "RecursionError" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "nested too deeply" in lines[0], r.stderr
    r = run_cli_here("runs", "info", str(tmp_path))
    assert "Traceback" not in r.stderr, r.stderr


def test_a_rewritten_real_recording_still_matches(tmp_path):
    """The crafting itself changes nothing: the same recording written again replays MATCH."""
    real = ROOT / "recordings" / "arc_rsi" / "controller.mcap"
    path = tmp_path / "controller.mcap"
    _rewrite(real, path, dict(read(real).metadata))
    shutil.copy(ROOT / "recordings" / "arc_rsi" / "rig.toml", tmp_path / "rig.toml")
    assert replay(path).exit_code == EXIT_MATCH
