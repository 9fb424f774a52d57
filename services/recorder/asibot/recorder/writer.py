"""A lean MCAP writer for the recorder's hot path.

mcap's own `Writer.add_message` builds a record object per message and caps the recorder
near 90 k msg/s on this machine; the budget is 100 k. Here a message costs one struct.pack,
two buffer appends and two appends to its channel's index. The message index records are
written here too, from those arrays in one go: mcap's MessageIndex.write packs entry by entry
(~0.5 us a message). Everything else (header, channels, chunks, chunk indexes, statistics,
summary, footer) is serialised by mcap's own record classes, so the file layout is the
library's. Readers: any MCAP reader; tests read files back with mcap's readers.
"""

from __future__ import annotations

import struct
import sys
import zlib
from array import array
from collections import defaultdict
from typing import BinaryIO

import zstandard
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Opcode, RecordBuilder,
                          Statistics, SummaryOffset)

MAGIC = b"\x89MCAP0\r\n"
TYPE_METADATA = "message_type"
"""Channel metadata naming the message type on a channel, so a listing needs no message."""
_MESSAGE = struct.Struct("<BQHIQQ")   # opcode, length, channel, sequence, log_time, publish_time
_MESSAGE_FIXED = 2 + 4 + 8 + 8
_MESSAGE_INDEX = struct.Struct("<BQHI")  # opcode, length, channel, length of the entries


def _message_index(channel_id: int, entries: array) -> bytes:
    """A MessageIndex record (MCAP spec) of one channel in one chunk."""
    if sys.byteorder != "little":  # the array holds native integers, MCAP is little-endian
        entries.byteswap()
    size = len(entries) * entries.itemsize
    return _MESSAGE_INDEX.pack(Opcode.MESSAGE_INDEX, 2 + 4 + size, channel_id, size) + entries.tobytes()


class LeanWriter:
    """Chunked (zstd), indexed MCAP; schema-less channels (schema id 0, self-describing encoding)."""

    def __init__(self, stream: BinaryIO, chunk_size: int = 1 << 20, level: int = 1) -> None:
        self._out = stream
        self._chunk_size = chunk_size
        self._zstd = zstandard.ZstdCompressor(level=level)
        self._pos = 0
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._counts: dict[int, int] = defaultdict(int)
        self._message_count = 0
        self._start = 0
        self._end = 0
        self._reset_chunk()

    def _reset_chunk(self) -> None:
        self._buf = bytearray()
        # Per channel, the (log_time, offset) of its messages in this chunk, flat.
        self._index: dict[int, array] = {}
        self._chunk_start = 2**64 - 1
        self._chunk_end = 0

    @property
    def size(self) -> int:
        """Bytes written so far, the open chunk not included."""
        return self._pos

    def _write(self, data: bytes) -> None:
        self._out.write(data)
        self._pos += len(data)

    def start(self, profile: str, library: str) -> None:
        self._write(MAGIC)
        rb = RecordBuilder()
        Header(profile=profile, library=library).write(rb)
        self._write(rb.end())

    def register_channel(self, topic: str, message_encoding: str, metadata: dict[str, str] | None = None) -> int:
        cid = len(self._channels) + 1
        channel = Channel(id=cid, schema_id=0, topic=topic, message_encoding=message_encoding,
                          metadata=metadata or {})
        self._channels[cid] = channel
        # The channel record goes into the current chunk, ahead of its first message, so a
        # streaming reader of a truncated file still knows every channel it meets.
        rb = RecordBuilder()
        channel.write(rb)
        self._buf += rb.end()
        return cid

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        head = _MESSAGE.pack(Opcode.MESSAGE, _MESSAGE_FIXED + len(data), channel_id, sequence,
                             log_time, publish_time)  # first: a bad time raises before anything is added
        buf = self._buf
        index = self._index.get(channel_id)
        if index is None:
            index = self._index[channel_id] = array("Q")
        index.append(log_time)
        index.append(len(buf))
        buf += head
        buf += data
        if log_time < self._chunk_start:
            self._chunk_start = log_time
        if log_time > self._chunk_end:
            self._chunk_end = log_time
        if len(buf) >= self._chunk_size:
            self.flush()

    def flush(self) -> None:
        """Close the current chunk (compressed, followed by its message indexes)."""
        if not self._index:
            return
        raw = self._buf  # compressed as it is: a new chunk gets a new buffer
        compressed = self._zstd.compress(raw)
        rb = RecordBuilder()
        Chunk(compression="zstd", data=compressed, message_start_time=self._chunk_start,
              message_end_time=self._chunk_end, uncompressed_crc=zlib.crc32(raw),
              uncompressed_size=len(raw)).write(rb)
        chunk_bytes = rb.end()
        chunk_offset = self._pos
        self._write(chunk_bytes)
        offsets: dict[int, int] = {}
        index_start = self._pos
        n = 0
        for cid, entries in self._index.items():
            offsets[cid] = self._pos
            self._write(_message_index(cid, entries))
            count = len(entries) // 2
            self._counts[cid] += count
            n += count
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=self._chunk_start, message_end_time=self._chunk_end,
            chunk_start_offset=chunk_offset, chunk_length=len(chunk_bytes),
            message_index_offsets=offsets, message_index_length=self._pos - index_start,
            compression="zstd", compressed_size=len(compressed), uncompressed_size=len(raw)))
        if self._message_count == 0:
            self._start = self._chunk_start
        self._start = min(self._start, self._chunk_start)
        self._end = max(self._end, self._chunk_end)
        self._message_count += n
        self._reset_chunk()

    def finish(self) -> None:
        """Write the summary and footer, so seeking readers can index the file."""
        self.flush()
        rb = RecordBuilder()
        DataEnd(data_section_crc=0).write(rb)
        self._write(rb.end())
        summary_start = self._pos
        groups: list[SummaryOffset] = []
        summary = RecordBuilder()

        def group(opcode: int, records: list) -> None:
            begin = summary.count
            for rec in records:
                rec.write(summary)
            groups.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + begin,
                                        group_length=summary.count - begin))

        group(Opcode.CHANNEL, list(self._channels.values()))
        group(Opcode.STATISTICS, [Statistics(
            message_count=self._message_count, schema_count=0, channel_count=len(self._channels),
            attachment_count=0, metadata_count=0, chunk_count=len(self._chunk_indexes),
            message_start_time=self._start, message_end_time=self._end,
            channel_message_counts=dict(self._counts))])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        offset_start = summary_start + summary.count
        for g in groups:
            g.write(summary)
        body = summary.end()
        self._write(body)
        Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=0).write(rb)
        self._write(rb.end())
        self._write(MAGIC)
