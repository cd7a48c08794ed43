"""``--foxglove`` and ``--mcap`` of ``run`` and ``serve``: the run's live streams
(:class:`~mmexec.executive.serve.service.Streams`) to a Foxglove server and an MCAP file.

Order: build the runner and :meth:`Runner.prepare` it (bad input fails before anything is
opened), then :meth:`Recording.attach` (creates the MCAP file, starts the server: a path
or address that cannot be used is an InputError located at its option), run, and
:meth:`Recording.close` in a ``finally``. A recording is made of what the skills read:
with ``--mcap`` the sensors are tapped on any clock (see
:class:`~mmexec.executive.serve.service.Streams`), so a seeded run writes the same event
log with or without it. A run that never started (its event log could not be opened)
leaves no MCAP file behind.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from mmexec.config.yamlload import InputError, Mark
from mmexec.executive.recording.channels import Recorder
from mmexec.executive.recording.foxglove_server import DEFAULT_FOXGLOVE, FoxgloveServer
from mmexec.executive.recording.mcapfile import McapFile, McapOpenError
from mmexec.executive.runner import Runner
from mmexec.executive.serve.server import parse_bind
from mmexec.executive.serve.service import Streams
from mmexec.executive.serve.settings import ServeSettings, parse_section

__all__ = ["DEFAULT_FOXGLOVE", "Recording", "open_mcap"]

log = logging.getLogger(__name__)


def open_mcap(path: Path, *, overwrite: bool, option: str = "--mcap") -> McapFile:
    """:class:`McapFile` at ``path``, open; InputError located at the path otherwise."""
    try:
        return McapFile(path, overwrite=overwrite).open()
    except McapOpenError as e:
        hint = "; pass --overwrite to replace it" if e.exists else ""
        raise InputError.at(Mark(str(path), 1, 1), f"{option}: {e.reason}{hint}") from None


class Recording:
    """The Foxglove server (``foxglove``: HOST:PORT) and MCAP file (``mcap``) of one run.
    Either may be None. HOST:PORT is checked at construction (InputError)."""

    def __init__(self, *, foxglove: str | None = None, mcap: Path | None = None, overwrite: bool = False) -> None:
        self.bind = parse_bind(foxglove, "--foxglove", DEFAULT_FOXGLOVE) if foxglove is not None else None
        self.mcap_path = mcap
        self.overwrite = overwrite
        self.server: FoxgloveServer | None = None
        self.mcap: McapFile | None = None
        self.recorders: list[Recorder] = []

    def attach(self, runner: Runner) -> None:
        """Open the outputs and connect them to ``runner``'s streams (a prepared
        :class:`Runner`, or a ServeRunner, whose streams also feed the console)."""
        streams: Streams | None = getattr(runner, "streams", None)
        if streams is None:
            streams = Streams(runner.world)
            _connect(runner, streams)
        try:
            if self.mcap_path is not None:
                self.mcap = open_mcap(self.mcap_path, overwrite=self.overwrite)
                self.recorders.append(Recorder(self.mcap))
                streams.tap = True  # record what the skills read, on any clock
            if self.bind is not None:
                self.server = FoxgloveServer(self.bind, _settings(runner))
                self.server.start()
                self.recorders.append(Recorder(self.server))
        except BaseException:
            self.close()
            raise
        for rec in self.recorders:
            streams.add_sink(rec)

    def describe(self) -> list[str]:
        """What is served and recorded, one line each, for the run's console."""
        lines = []
        if self.server is not None:
            lines.append(f"foxglove: {self.server.url()} (open it in Foxglove: Open connection, Foxglove WebSocket)")
        if self.mcap is not None:
            lines.append(f"recording: {self.mcap.path}")
        return lines

    def close(self) -> None:
        """Finish the recording and stop the server (idempotent). An MCAP file of a run
        that never started is removed."""
        for rec in self.recorders:
            rec.close()
        for out in (self.server, self.mcap):
            if out is not None:
                out.close()
        if self.mcap is not None and self.mcap.error is None and not any(
                r.started for r in self.recorders if r.output is self.mcap):
            self.mcap.path.unlink(missing_ok=True)
        elif self.mcap is not None and self.mcap.error is not None:
            log.warning("--mcap %s: the recording is incomplete: %s", self.mcap.path,
                        self.mcap.error.strerror or self.mcap.error)


def _connect(runner: Runner, streams: Streams) -> None:
    """A plain :class:`Runner`'s records and ticks to ``streams``; the robot's sensors are
    tapped and the map sent once the run has started (its ``run_start`` record)."""

    def on_record(record: dict[str, Any]) -> None:
        streams.on_record(record)
        if record.get("event") == "run_start" and runner.robot is not None:
            streams.start(runner.robot)

    runner.add_log_listener(on_record)
    runner.add_tick_hook(lambda robot, period: streams.publish(robot))


def _settings(runner: Runner) -> ServeSettings:
    """The stream rates: the service's settings, else the config's ``serve:`` section."""
    service = getattr(runner, "service", None)
    if service is not None:
        return service.settings  # type: ignore[no-any-return]
    assert runner.config is not None
    return parse_section(runner.config.config.serve, runner.config.mark("serve"))
