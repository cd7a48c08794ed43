"""``mmexec log export LOG.jsonl --mcap OUT.mcap``: an event log as an MCAP file.

The log holds the run's records, not its sensor data, so the file has the event-derived
channels filled (``/mmexec/events``, ``/mmexec/log``, ``/mmexec/tree``, see
:mod:`mmexec.executive.recording.channels`) and the robot's channels registered but
empty; for those, record the run with ``--mcap``. The messages on the event-derived
channels are those a live ``--mcap`` recording of the same run has.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

from mmexec.executive.recording.channels import ChannelOutput, Recorder

__all__ = ["export_records"]


def export_records(records: Iterable[Mapping[str, Any]], output: ChannelOutput) -> Counter[str]:
    """Write every record to ``output`` (then closed); messages per channel. A record
    without a usable ``t`` is placed at the time of the one before it."""
    recorder = Recorder(output)
    t = 0.0
    try:
        for record in records:
            value = record.get("t")
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                t = float(value)
            recorder.record(record, t)
    finally:
        recorder.close()
    return recorder.counts
