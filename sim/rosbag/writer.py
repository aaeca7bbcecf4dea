"""Writing rosbag2 bags in MCAP storage, without ROS.

:class:`BagWriter` writes one ``.mcap`` file the way rosbag2's MCAP storage plugin does
(profile ``ros2``, message definitions as ``ros2msg`` schemas, CDR messages, a channel
per topic), so ``ros2 bag info/play``, Foxglove, PlotJuggler, the ``mcap`` tools and
``rosbags`` all open it. Messages are serialized by ``rosbags``' type store
(:mod:`sim.rosbag.messages`); the container is written by the ``mcap`` library with
zstd-compressed chunks. Stamps must not go back in time on a topic: a bag whose stamps
do on one topic would replay out of order in every tool.
"""

from __future__ import annotations

from pathlib import Path

from mcap.writer import CompressionType, Writer

from autonomy.common.errors import InputError
from sim.rosbag.messages import typestore


class BagWriter:
    """One MCAP file of ROS 2 messages; topics are declared on first use."""

    def __init__(self, path: str | Path, library: str = "depthnav") -> None:
        self.path = Path(path)
        if self.path.suffix != ".mcap":
            raise InputError(f"--bag {self.path}: expected a file name ending in .mcap (a rosbag2 in MCAP storage)")
        if self.path.parent and not self.path.parent.exists():
            raise InputError(f"--bag {self.path}: directory {self.path.parent} does not exist")
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._last: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.messages = 0
        """Messages written so far."""

    def _channel(self, topic: str, msgtype: str) -> int:
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != msgtype:
                raise ValueError(f"topic {topic}: declared as {known[1]}, written as {msgtype}")
            return known[0]
        sid = self._schemas.get(msgtype)
        if sid is None:
            msgdef, _ = typestore().generate_msgdef(msgtype, ros_version=2)
            sid = self._writer.register_schema(name=msgtype, encoding="ros2msg", data=msgdef.encode())
            self._schemas[msgtype] = sid
        cid = self._writer.register_channel(topic=topic, message_encoding="cdr", schema_id=sid, metadata={"offered_qos_profiles": ""})
        self._channels[topic] = (cid, msgtype)
        return cid

    def write(self, topic: str, t_ns: int, msg) -> None:
        """Serialize ``msg`` (a ``rosbags`` message object) onto ``topic`` at ``t_ns``."""
        msgtype = msg.__msgtype__
        cid = self._channel(topic, msgtype)
        if t_ns < self._last.get(topic, -1):
            raise ValueError(f"topic {topic}: stamp {t_ns} ns goes back in time (last {self._last[topic]} ns)")
        self._last[topic] = t_ns
        seq = self._seq.get(topic, 0)
        self._seq[topic] = seq + 1
        data = typestore().serialize_cdr(msg, msgtype)
        self._writer.add_message(channel_id=cid, log_time=t_ns, data=bytes(data), publish_time=t_ns, sequence=seq)
        self.messages += 1

    def close(self) -> None:
        """Write the summary and close the file (a bag without it is still readable)."""
        if self._file.closed:
            return
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
