"""MCAP files of the Foxglove channels (``--mcap FILE``, ``mmexec log export``), written
with the ``mcap`` library: zstd-compressed chunks of at most :data:`CHUNK_BYTES`, message
and chunk indexes, statistics, and every channel of
:data:`~mmexec.executive.recording.channels.CHANNELS` registered when the file opens (a
channel nothing was sent on is still listed).

A file is never silently replaced: it is created exclusively unless ``overwrite``
(then only a regular file is truncated), never through a symbolic link, and locked
(``flock``) while written, like the event log. A write that fails (a full disk) stops the
recording, keeps the error in :attr:`McapFile.error` and logs it once; the run goes on,
its event log being the canonical record. A killed process leaves the file without its
summary and its last chunk (``mcap recover`` rebuilds the rest).
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import stat
from pathlib import Path
from typing import BinaryIO, Self

from mcap.writer import CompressionType, Writer

from mmexec.executive.recording.channels import CHANNELS, ChannelSpec

__all__ = ["CHUNK_BYTES", "RECORD_POSE_HZ", "McapFile", "McapOpenError"]

log = logging.getLogger(__name__)

#: Uncompressed bytes per chunk: what a killed process may lose at most.
CHUNK_BYTES = 256 * 1024
#: [clock Hz] how often the base pose is recorded at most (every tick at the usual 20 Hz).
RECORD_POSE_HZ = 20.0
#: [clock s] two times closer than this are one tick (rate limits).
_TICK_SLACK = 1e-6


class McapOpenError(Exception):
    """The MCAP file cannot be created: ``str(e)`` is ``PATH: reason`` (one line);
    :attr:`exists` when only ``overwrite`` was missing."""

    def __init__(self, path: Path, reason: str, *, exists: bool = False) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason
        self.exists = exists


def _create(path: Path, overwrite: bool) -> BinaryIO:
    """``path`` opened for writing a new file (see the module doc). McapOpenError."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise McapOpenError(path, f"cannot create its folder: {e.strerror or e}") from None
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | (0 if overwrite else os.O_EXCL)
    try:
        fd = os.open(path, flags, 0o644)
    except FileExistsError:
        if path.is_symlink() or not path.is_file():
            raise McapOpenError(path, "exists and is not a regular file") from None
        raise McapOpenError(path, "already exists", exists=True) from None
    except OSError as e:
        if e.errno in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
            raise McapOpenError(path, "is not a regular file (a symbolic link, folder or FIFO)") from None
        raise McapOpenError(path, f"cannot open for writing: {e.strerror or e}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise McapOpenError(path, "is not a regular file")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise McapOpenError(path, "is in use: another process is writing it") from None
        os.ftruncate(fd, 0)
        os.set_blocking(fd, True)
    except (McapOpenError, OSError) as e:
        os.close(fd)
        if isinstance(e, McapOpenError):
            raise
        raise McapOpenError(path, f"cannot prepare for writing: {e.strerror or e}") from None
    return os.fdopen(fd, "wb")


class McapFile:
    """A :class:`~mmexec.executive.recording.channels.ChannelOutput` writing an MCAP file.

    ``pose_hz`` [clock Hz] limits the pose; scans and camera frames are all taken (the
    live streams hand over each new reading a skill took, at most one per tick).
    """

    def __init__(self, path: str | Path, *, overwrite: bool = False, pose_hz: float = RECORD_POSE_HZ) -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        self.pose_hz = pose_hz
        #: the OSError that stopped the recording; None while all is well
        self.error: OSError | None = None
        self._stream: BinaryIO | None = None
        self._writer: Writer | None = None
        self._ids: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self._next_pose = 0.0

    def open(self, channels: tuple[ChannelSpec, ...] = CHANNELS) -> Self:
        """Create the file and register the channels. Raises :class:`McapOpenError`."""
        self._stream = _create(self.path, self.overwrite)
        try:
            self._writer = Writer(self._stream, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
            self._writer.start(profile="", library="mmexec")
            for spec in channels:
                sid = self._writer.register_schema(spec.schema_name, spec.schema_encoding, spec.schema_data)
                self._ids[spec.topic] = self._writer.register_channel(spec.topic, spec.message_encoding, sid)
                self._seq[spec.topic] = 0
        except OSError as e:
            self._stream.close()
            self._stream = None
            raise McapOpenError(self.path, f"cannot write: {e.strerror or e}") from None
        return self

    @property
    def closed(self) -> bool:
        return self._stream is None

    def write(self, topic: str, data: bytes, log_time: int) -> None:
        if self._writer is None or self.error is not None:
            return
        seq = self._seq[topic]
        self._seq[topic] = seq + 1
        try:
            self._writer.add_message(self._ids[topic], log_time=log_time, data=data, publish_time=log_time,
                                     sequence=seq)
        except OSError as e:
            self._failed(e)

    def takes(self, topic: str, t: float) -> bool:
        if topic != "pose":
            return True
        if t + _TICK_SLACK < self._next_pose:
            return False
        self._next_pose = t + 1.0 / self.pose_hz
        return True

    def tick(self, log_time: int) -> None:
        """Nothing to do per tick."""

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        stream, self._stream = self._stream, None
        if stream is None:
            return
        writer, self._writer = self._writer, None
        try:
            try:
                if writer is not None and self.error is None:
                    writer.finish()
            finally:
                stream.close()  # a buffered stream is closed even when its last flush fails
        except OSError as e:
            self._failed(e)

    def _failed(self, e: OSError) -> None:
        if self.error is not None:
            return
        self.error = e
        log.error("--mcap %s: write failed: %s; the recording stopped here (the event log goes on)",
                  self.path, e.strerror or e)
