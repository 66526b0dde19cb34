"""``autopilot replay`` on damaged recordings: each damage, made at test time from a real small
recording of the flight recorder, is one line naming the problem and where it is (byte offset,
channel), never a traceback; memory stays bounded whatever a file says of itself; a file cut
off reads up to its cut; and a recording with nothing to compare does not pass."""

from __future__ import annotations

import base64
import functools
import json
import random
import struct
import subprocess
import sys
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from app import recording
from app.cli import main
from app.protocol import events as ev
from app.recording import EVENT_CHANNELS, IMAGE_TOPIC, CutOff, RecordingError
from tests.helpers.recordings import small_recording

REPO = Path(__file__).resolve().parents[2]
GOALS = EVENT_CHANNELS[ev.GoalApplied].topic
MAGIC = b"\x89MCAP0\r\n"


@pytest.fixture(scope="module")
def real(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished recording of about a second, in several chunks."""
    return small_recording(tmp_path_factory.mktemp("real"))


def _replay(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, list[str], str]:
    """Exit status, stderr lines and stdout of ``autopilot replay args``."""
    status = main(["replay", *map(str, args)])
    out, err = capsys.readouterr()
    return status, err.splitlines(), out


def _rewrite(source: Path, target: Path, change: Callable[[str, dict[str, Any]], Any]) -> None:
    """``source`` written again as the recorder would, each message's fields through
    ``change(topic, fields)`` (whatever it returns is the message's JSON)."""
    with source.open("rb") as stream, target.open("wb") as out:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start()
        schemas = {
            schema_id: writer.register_schema(schema.name, schema.encoding, schema.data)
            for schema_id, schema in summary.schemas.items()
        }
        channels = {
            channel_id: writer.register_channel(
                channel.topic, channel.message_encoding, schemas[channel.schema_id]
            )
            for channel_id, channel in summary.channels.items()
        }
        for _, channel, message in reader.iter_messages(log_time_order=False):
            data = json.dumps(change(channel.topic, json.loads(message.data))).encode()
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time)
        writer.finish()  # type: ignore[no-untyped-call]


def _first(topic: str, damaged: Callable[[dict[str, Any]], Any]) -> Callable[..., Any]:
    """A change for :func:`_rewrite`: the first message on ``topic`` becomes ``damaged(it)``."""
    done = [False]

    def change(on: str, fields: dict[str, Any]) -> Any:
        if on != topic or done[0]:
            return fields
        done[0] = True
        return damaged(fields)

    return change


def _png(fields: dict[str, Any]) -> dict[str, Any]:
    bgr = cv2.imdecode(np.frombuffer(base64.b64decode(fields["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert bgr is not None
    png = cv2.imencode(".png", bgr)[1].tobytes()
    return {**fields, "data": base64.b64encode(png).decode()}


DAMAGED_MESSAGES = {
    "a goal that is a JSON array": (GOALS, lambda fields: [1, 2], "is not a JSON object"),
    "a goal that is not a goal": (GOALS, lambda f: {**f, "x": "left"}, "not a 'goal' event"),
    "a frame tag that is a list": (
        IMAGE_TOPIC,
        lambda fields: {**fields, "frame": [fields["frame"]]},
        "frame tag that is not an integer",
    ),
    "an image that is a PNG": (IMAGE_TOPIC, _png, "not a JPEG"),
    "an image that is not base64": (
        IMAGE_TOPIC,
        lambda fields: {**fields, "data": "%%%"},
        "not base64",
    ),
}


@pytest.mark.parametrize(
    ("topic", "damage", "said"), DAMAGED_MESSAGES.values(), ids=list(DAMAGED_MESSAGES)
)
def test_a_damaged_message_is_one_line_naming_its_channel_and_offset(
    real: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    topic: str,
    damage: Callable[[dict[str, Any]], Any],
    said: str,
) -> None:
    damaged = tmp_path / "damaged.mcap"
    _rewrite(real, damaged, _first(topic, damage))
    status, err, _ = _replay(capsys, damaged)
    assert status == 2, err
    [line] = err
    assert line.startswith("autopilot replay: cannot read the recording: "), line
    assert f"the message on {topic} at byte " in line and said in line, line


@pytest.mark.parametrize("seed", range(8))
def test_flipped_bits_are_one_line_with_their_offset(
    real: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], seed: int
) -> None:
    # 50 bits flipped anywhere in the file: each chunk's checksum (or its framing) finds them.
    data = bytearray(real.read_bytes())
    rng = random.Random(seed)
    for _ in range(50):
        data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    damaged = tmp_path / "flipped.mcap"
    damaged.write_bytes(bytes(data))
    for options in ([], ["--summary"]):
        status, err, _ = _replay(capsys, *options, damaged)
        assert status == 2, err
        [line] = err
        assert "cannot read the recording: " in line and " byte " in line, line


def test_an_empty_file_and_one_that_is_not_mcap_are_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    status, err, _ = _replay(capsys, empty)
    assert (status, err) == (2, [f"autopilot replay: cannot read the recording: {empty} is empty"])
    text = tmp_path / "text.mcap"
    text.write_bytes(b"hello, world\n")
    status, err, _ = _replay(capsys, text)
    assert status == 2 and len(err) == 1 and "is not an MCAP file" in err[0], err


def _record_offsets(path: Path) -> list[tuple[int, int]]:
    """(offset, opcode) of each record of a file's data section, read here on their own."""
    data = path.read_bytes()
    offset, found = len(MAGIC), []
    while True:
        opcode, length = struct.unpack_from("<BQ", data, offset)
        found.append((offset, opcode))
        if opcode == 0x0F:  # data end
            return found
        offset += 9 + length


def test_a_huge_record_length_in_a_finished_file_is_damage_at_its_offset(
    real: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = bytearray(real.read_bytes())
    chunk = next(offset for offset, opcode in _record_offsets(real) if opcode == 0x06)
    struct.pack_into("<Q", data, chunk + 1, 2**62)
    damaged = tmp_path / "huge.mcap"
    damaged.write_bytes(bytes(data))
    status, err, _ = _replay(capsys, damaged)
    assert status == 2, err
    [line] = err
    assert f"{damaged} is damaged at byte {chunk}: its chunk record says {2**62} bytes" in line


def test_a_file_cut_off_reads_up_to_its_cut_and_says_where(
    real: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    whole = list(recording.messages([real]))
    chunks = [offset for offset, opcode in _record_offsets(real) if opcode == 0x06]
    # Cut inside the third chunk: what the first two hold reads, typed, in order.
    cut_at = chunks[2] + 100
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(real.read_bytes()[:cut_at])
    cuts: list[CutOff] = []
    before = list(recording.messages([cut], cuts.append))
    assert 0 < len(before) < len(whole) and before == whole[: len(before)]
    [said] = cuts
    assert f"{cut} is cut off at byte {chunks[2]}: its chunk record says" in str(said)
    with pytest.raises(CutOff):
        list(recording.messages([cut]))
    # The summary counts what reads, and says the cut in one line.
    status, err, out = _replay(capsys, "--summary", "--json", cut)
    assert status == 0, err
    assert err == [f"autopilot replay: {said}; reading what comes before it"]
    counted = json.loads(out.splitlines()[-1])["channels"]
    assert sum(entry["messages"] for entry in counted.values()) == len(before)
    # Cut inside a record's header, and right after the magic: nothing whole, nothing compared.
    for length in (chunks[0] + 4, len(MAGIC)):
        cut.write_bytes(real.read_bytes()[:length])
        status, err, _ = _replay(capsys, cut)
        assert status == 1, err
        assert err[0].startswith(f"autopilot replay: {cut} is cut off at byte "), err
        assert "nothing to compare" in err[1], err


def _messages_per_record(path: Path) -> list[tuple[int, int]]:
    """(end offset, messages it holds) of each record of a file's data section before its data
    end, counted here on their own: a chunk's records walked after zstd, a message record one."""
    data = path.read_bytes()
    found = []
    for offset, opcode in _record_offsets(path):
        if opcode == 0x0F:
            return found
        (length,) = struct.unpack_from("<Q", data, offset + 1)
        held = 0
        if opcode == 0x05:
            held = 1
        elif opcode == 0x06:
            # Chunk: times (16), size (8), CRC (4), compression (4 + 4), records (8 + ...).
            records = zstandard.ZstdDecompressor().decompress(
                data[offset + 9 + 44 : offset + 9 + length],
                max_output_size=struct.unpack_from("<Q", data, offset + 9 + 16)[0],
            )
            at = 0
            while at < len(records):
                inner, inner_length = struct.unpack_from("<BQ", records, at)
                held += inner == 0x05
                at += 9 + inner_length
        found.append((offset + 9 + length, held))
    raise AssertionError("no data end")


def test_a_cut_at_any_byte_near_a_record_s_end_is_a_cut_never_damage(
    real: Path, tmp_path: Path
) -> None:
    # Cut a few bytes before, at and after each record's end (inside the next record's header
    # and just past it): the file reads as cut off, with every message of the whole records
    # before the cut, no more, no fewer.
    original = real.read_bytes()
    whole = list(recording.messages([real]))
    ends = _messages_per_record(real)
    assert sum(1 for _, held in ends if held) >= 3, ends  # several chunks
    # The records up to the third that holds messages: the arithmetic is the same for every
    # record, and a cut early in the file reads less.
    third = [i for i, (_, held) in enumerate(ends) if held][2]
    cut = tmp_path / "cut.mcap"
    tried = 0
    for end, _ in ends[: third + 1]:
        for at in range(end - 10, min(end + 12, ends[-1][0] + 1)):
            if at <= len(MAGIC):
                continue
            cut.write_bytes(original[:at])
            cuts: list[CutOff] = []
            read = list(recording.messages([cut], cuts.append))
            expected = sum(held for e, held in ends if e <= at)
            assert read == whole[:expected], at
            assert len(cuts) == 1 and f"{cut} is cut off at byte " in str(cuts[0]), at
            tried += 1
    assert tried > 100


def test_a_recording_with_nothing_to_compare_does_not_pass(
    real: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The goals are there, the images are of other frames: no goal can be checked.
    elsewhere = tmp_path / "elsewhere.mcap"
    _rewrite(
        real,
        elsewhere,
        lambda topic, fields: (
            {**fields, "frame": fields["frame"] + 10_000} if topic == IMAGE_TOPIC else fields
        ),
    )
    status, err, out = _replay(capsys, "--json", elsewhere)
    assert status == 1 and out == "", (err, out)
    [line] = err
    # Every goal the recording holds is counted (how many a real-time second of recording
    # holds depends on the machine's load: counted here on their own).
    goals = sum(topic == GOALS for topic, _, _ in recording.messages([real]))
    assert goals > 0
    assert line.startswith(f"autopilot replay: nothing to compare: {goals} goals"), line


@functools.cache
def _zeros(holds: int) -> tuple[bytes, int]:
    """A chunk's data, one message of ``holds`` bytes, zeros after its channel: zstd, and its
    CRC."""
    inner = struct.pack("<BQH", 0x05, holds - 9, 1) + bytes(holds - 11)  # on channel 1
    return zstandard.ZstdCompressor().compress(inner), zlib.crc32(inner)


def _bomb(path: Path, holds: int, says: int) -> None:
    """A small file whose one zstd chunk holds ``holds`` bytes (one message, all zeros) and
    says it holds ``says``."""
    _one_chunk(path, *_zeros(holds), says)


def _one_chunk(path: Path, compressed: bytes, crc: int, says: int) -> None:
    """A finished file of one zstd chunk, ``compressed`` (its records' CRC ``crc``), which says
    it holds ``says`` bytes."""
    schema = b"\x01\x00" + struct.pack("<I", 3) + b"any" + struct.pack("<I", 10) + b"jsonschema"
    schema += struct.pack("<I", 2) + b"{}"
    channel = struct.pack("<HH", 1, 1) + struct.pack("<I", len(GOALS)) + GOALS.encode()
    channel += struct.pack("<I", 4) + b"json" + struct.pack("<I", 0)
    chunk = struct.pack("<QQQI", 0, 0, says, crc) + struct.pack("<I", 4) + b"zstd"
    chunk += struct.pack("<Q", len(compressed)) + compressed
    header = struct.pack("<I", 0) + struct.pack("<I", 0)
    with path.open("wb") as out:
        out.write(MAGIC)
        for opcode, body in ((0x01, header), (0x03, schema), (0x04, channel), (0x06, chunk)):
            out.write(struct.pack("<BQ", opcode, len(body)) + body)
        out.write(struct.pack("<BQ", 0x0F, 4) + bytes(4))
        out.write(struct.pack("<BQ", 0x02, 20) + bytes(20) + MAGIC)


def test_a_chunk_may_expand_by_the_smaller_of_its_two_bounds(tmp_path: Path) -> None:
    # Below the chunk limit, the expansion limit refuses: zeros that expand honestly to far more
    # than EXPANSION_LIMIT times their compressed size, though far less than CHUNK_LIMIT.
    holds = 400_000
    compressed, crc = _zeros(holds)
    limit = recording.EXPANSION_LIMIT * len(compressed)
    assert limit < holds < recording.CHUNK_LIMIT
    path = tmp_path / "expands.mcap"
    _one_chunk(path, compressed, crc, says=holds)
    with pytest.raises(RecordingError) as refused:
        list(recording.messages([path]))
    said = f"says it holds {holds} bytes in {len(compressed)}: more than a recording's chunk may"
    assert f"{said} ({limit})" in str(refused.value)
    # Above it, the chunk limit refuses, though the chunk is large enough to expand that far.
    noise = random.Random(5).randbytes(recording.CHUNK_LIMIT // recording.EXPANSION_LIMIT + 1000)
    compressed = zstandard.ZstdCompressor().compress(noise)
    assert recording.EXPANSION_LIMIT * len(compressed) > recording.CHUNK_LIMIT
    _one_chunk(path, compressed, zlib.crc32(noise), says=recording.CHUNK_LIMIT + 1)
    with pytest.raises(RecordingError) as refused:
        list(recording.messages([path]))
    assert f"more than a recording's chunk may ({recording.CHUNK_LIMIT})" in str(refused.value)


def _peak_rss_mb(runs: list[list[str]]) -> list[tuple[int, str, float]]:
    """Exit status, stderr and the peak resident size (MB) so far, after each of ``runs`` of
    ``autopilot replay``, one after the other in one process of its own."""
    code = (
        "import contextlib, io, json, sys\n"
        "from app.cli import main\n"
        "for args in json.loads(sys.argv[1]):\n"
        "    with contextlib.redirect_stderr(io.StringIO()) as err:\n"
        "        status = main(['replay', *args])\n"
        # VmHWM, not getrusage's ru_maxrss, which a process inherits from the one it forked.
        "    status_lines = open('/proc/self/status').read().splitlines()\n"
        "    [peak] = [int(line.split()[1]) / 1024 for line in status_lines if 'VmHWM' in line]\n"
        "    print('peak', json.dumps([status, err.getvalue(), peak]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, json.dumps(runs)],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    )
    # Among what the runs write on stdout (a summary's listing).
    found = [line.removeprefix("peak ") for line in done.stdout.splitlines() if "peak " in line]
    return [tuple(json.loads(line)) for line in found]


def test_a_zstd_bomb_is_refused_without_its_memory(real: Path, tmp_path: Path) -> None:
    holds = 256 * 2**20
    honest, lying = tmp_path / "honest.mcap", tmp_path / "lying.mcap"
    _bomb(honest, holds, says=holds)
    _bomb(lying, holds, says=16 * 1024)
    assert honest.stat().st_size < 64 * 1024
    # First a real recording's summary, the baseline; then the bombs, replayed and summarised.
    bombs = [[*options, str(bomb)] for bomb in (honest, lying) for options in ([], ["--summary"])]
    (status, err, baseline_mb), *refused = _peak_rss_mb([["--summary", str(real)], *bombs])
    assert status == 0, err
    saids = [f"says it holds {holds} bytes in"] * 2 + ["not the more"] * 2
    for (status, err, peak_mb), said in zip(refused, saids, strict=True):
        # The bomb's 256 MiB never comes near.
        assert peak_mb < baseline_mb + 32, (peak_mb, baseline_mb)
        assert status == 2 and said in err and len(err.splitlines()) == 1, err


def test_a_seeded_fuzz_of_damaged_files_is_always_a_named_problem(
    real: Path, tmp_path: Path
) -> None:
    # Bytes flipped, dropped, repeated and cut, 300 files: each reads, or is a RecordingError
    # (a CutOff among them), never another exception.
    original = real.read_bytes()
    rng = random.Random(37)
    path = tmp_path / "fuzzed.mcap"
    outcomes = {"read": 0, "refused": 0}
    for _ in range(300):
        data = bytearray(original)
        for _ in range(rng.randrange(1, 6)):
            at = rng.randrange(len(data))
            match rng.randrange(4):
                case 0:
                    data[at] = rng.randrange(256)
                case 1:
                    del data[at : at + rng.randrange(1, 64)]
                case 2:
                    data[at:at] = data[at : at + rng.randrange(1, 64)]
                case _:
                    del data[at:]
        path.write_bytes(bytes(data))
        try:
            list(recording.events([path]))
            list(recording.images([path]))
            recording.summary([path])
            outcomes["read"] += 1
        except RecordingError:
            outcomes["refused"] += 1
    assert outcomes["refused"] > 200, outcomes
